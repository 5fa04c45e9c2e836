//! Analytic shapes, each defined in its own object space.
//!
//! Rays reach these functions already transformed into object space by the
//! instance's inverse transform; their direction is *not* normalised, so
//! the returned `t` is the same parameter as on the world-space ray.
//! Normals are returned in object space, pointing outward (along the
//! gradient of the implicit function for the quadrics); the caller maps
//! them to world space with the inverse transpose.
//!
//! Extents (all shapes are centred on the object-space origin, axis `+Y`):
//!
//! | shape | surface | extent |
//! |---|---|---|
//! | `Sphere { radius }` | `x²+y²+z² = r²` | closed |
//! | `Plane` | `y = 0`, normal `+Y` | infinite |
//! | `Disk { radius }` | `y = 0`, `x²+z² <= r²`, normal `+Y` | |
//! | `Polygon { vertices }` | convex, planar, counter-clockwise seen from the normal side | |
//! | `Cylinder { radius, y_min, y_max }` | `x²+z² = r²` | `y_min <= y <= y_max`, open ends |
//! | `Cone { radius, height }` | `x²+z² = (r (1 - y/h))²` | `0 <= y <= h` (apex at `y = h`), open base |
//! | `Ellipsoid { radii }` | `x²/a²+y²/b²+z²/c² = 1` | closed |
//! | `Paraboloid { radius, height }` | `y = h (x²+z²)/r²` | `0 <= y <= h`, open top |
//! | `Hyperboloid { waist_radius, top_radius, half_height }` | one sheet, `(x²+z²)/a² - y²/c² = 1` | `\|y\| <= half_height`, radius `top_radius` at the ends |

use std::sync::Arc;

use bevy_ecs::component::Component;
use glam::{Vec2, Vec3, Vec3A};

use crate::core::math::Ray;

mod planar;
mod quadrics;
mod roots;

use planar::{intersect_disk, intersect_plane, intersect_polygon, validate_polygon};
pub use planar::{polygon_hit, polygon_normal, polygon_uv_axes};
use quadrics::{
    intersect_cone, intersect_cylinder, intersect_ellipsoid, intersect_hyperboloid,
    intersect_paraboloid, intersect_sphere, rebased,
};

/// An analytic surface in object space. See the module documentation for
/// each shape's equation and extent.
#[derive(Component, Clone, Debug, PartialEq)]
pub enum Shape {
    /// Sphere of `radius` centred at the origin.
    Sphere {
        /// Radius, positive.
        radius: f32,
    },
    /// The infinite plane `y = 0` with normal `+Y`; `uv = (x, z)`.
    Plane,
    /// A disk of `radius` in the plane `y = 0`, normal `+Y`.
    Disk {
        /// Radius, positive.
        radius: f32,
    },
    /// A convex planar polygon with at least three vertices.
    Polygon {
        /// Vertices in counter-clockwise order seen from the normal side.
        vertices: Arc<[Vec3]>,
    },
    /// An open cylinder around the `Y` axis.
    Cylinder {
        /// Radius, positive.
        radius: f32,
        /// Lower end.
        y_min: f32,
        /// Upper end, above `y_min`.
        y_max: f32,
    },
    /// An open cone: base of `radius` at `y = 0`, apex at `y = height`.
    Cone {
        /// Base radius, positive.
        radius: f32,
        /// Height, positive.
        height: f32,
    },
    /// An axis-aligned ellipsoid.
    Ellipsoid {
        /// Semi-axes along X, Y, Z, each positive.
        radii: Vec3,
    },
    /// A paraboloid opening towards `+Y`, reaching `radius` at `y = height`.
    Paraboloid {
        /// Radius of the open end, positive.
        radius: f32,
        /// Height, positive.
        height: f32,
    },
    /// A hyperboloid of one sheet around the `Y` axis.
    Hyperboloid {
        /// Radius at `y = 0` (the waist), positive.
        waist_radius: f32,
        /// Radius at `y = ±half_height`, larger than the waist.
        top_radius: f32,
        /// Half of the height, positive.
        half_height: f32,
    },
}

/// An intersection with a shape, in object space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShapeHit {
    /// Ray parameter of the hit.
    pub t: f32,
    /// Hit point in object space, projected back onto the surface: correct
    /// to a few ulps of its own coordinates, whereas `ray.at(t)` carries
    /// the rounding of the ray's origin, which for a distant origin is far
    /// larger (and is what makes secondary rays self-intersect at large
    /// scales). Transform it to world space for shading.
    pub point: Vec3A,
    /// Outward geometric normal in object space (not necessarily unit).
    pub normal: Vec3A,
    /// Surface parameterisation, used for textures.
    pub uv: Vec2,
}

impl ShapeHit {
    /// True when `t`, the point, the normal and `uv` are all finite: the
    /// hits [`Shape::intersect`] returns.
    #[inline]
    pub fn is_finite(&self) -> bool {
        self.t.is_finite()
            && self.point.is_finite()
            && self.normal.is_finite()
            && self.uv.is_finite()
    }
}

fn positive(name: &str, v: f32) -> Result<(), String> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(format!("{name} must be a positive finite number, got {v}"))
    }
}

impl Shape {
    /// The object-space derivatives `(dP/du, dP/dv)` of the surface point
    /// with respect to its texture coordinates at the hit `point` (with
    /// `normal` the hit's normal), for texture level of detail; `None`
    /// for shapes whose texture scale is not derived (lookups on them
    /// read the full-resolution texture).
    pub fn uv_tangents(&self, point: Vec3A, normal: Vec3A) -> Option<(Vec3A, Vec3A)> {
        match self {
            Shape::Plane => Some((Vec3A::X, Vec3A::Z)),
            Shape::Disk { radius } => Some((Vec3A::X * (2.0 * radius), Vec3A::Z * (2.0 * radius))),
            Shape::Polygon { .. } => {
                // The axes `intersect_polygon` projects onto.
                let n = normal.normalize();
                let reference = if n.x.abs() < 0.9 { Vec3A::X } else { Vec3A::Z };
                let u = (reference - n * n.dot(reference)).normalize();
                Some((u, u.cross(n)))
            }
            Shape::Sphere { .. } => {
                // u = phi / 2pi, v = theta / pi with theta from +Y.
                let rho = (point.x * point.x + point.z * point.z).sqrt();
                if rho <= 0.0 {
                    return None;
                }
                let du = Vec3A::new(-point.z, 0.0, point.x) * std::f32::consts::TAU;
                let dv = Vec3A::new(point.y * point.x / rho, -rho, point.y * point.z / rho)
                    * std::f32::consts::PI;
                Some((du, dv))
            }
            _ => None,
        }
    }

    /// Short lower-case name of the shape kind.
    pub fn kind_name(&self) -> &'static str {
        match self {
            Shape::Sphere { .. } => "sphere",
            Shape::Plane => "plane",
            Shape::Disk { .. } => "disk",
            Shape::Polygon { .. } => "polygon",
            Shape::Cylinder { .. } => "cylinder",
            Shape::Cone { .. } => "cone",
            Shape::Ellipsoid { .. } => "ellipsoid",
            Shape::Paraboloid { .. } => "paraboloid",
            Shape::Hyperboloid { .. } => "hyperboloid",
        }
    }

    /// Checks the parameters; the error names the offending one.
    pub fn validate(&self) -> Result<(), String> {
        match self {
            Shape::Sphere { radius } | Shape::Disk { radius } => positive("radius", *radius),
            Shape::Plane => Ok(()),
            Shape::Polygon { vertices } => validate_polygon(vertices),
            Shape::Cylinder {
                radius,
                y_min,
                y_max,
            } => {
                positive("radius", *radius)?;
                if !(y_min.is_finite() && y_max.is_finite() && y_max > y_min) {
                    return Err(format!(
                        "cylinder needs finite y_min < y_max, got {y_min} and {y_max}"
                    ));
                }
                Ok(())
            }
            Shape::Cone { radius, height } | Shape::Paraboloid { radius, height } => {
                positive("radius", *radius)?;
                positive("height", *height)
            }
            Shape::Ellipsoid { radii } => {
                positive("radii.x", radii.x)?;
                positive("radii.y", radii.y)?;
                positive("radii.z", radii.z)
            }
            Shape::Hyperboloid {
                waist_radius,
                top_radius,
                half_height,
            } => {
                positive("waist_radius", *waist_radius)?;
                positive("top_radius", *top_radius)?;
                positive("half_height", *half_height)?;
                if top_radius <= waist_radius {
                    return Err(format!(
                        "hyperboloid top_radius ({top_radius}) must exceed waist_radius ({waist_radius})"
                    ));
                }
                Ok(())
            }
        }
    }

    /// Object-space bounding box `(min, max)`, or `None` for unbounded shapes.
    pub fn bounds(&self) -> Option<(Vec3A, Vec3A)> {
        let b = |min: Vec3, max: Vec3| Some((Vec3A::from(min), Vec3A::from(max)));
        match self {
            Shape::Sphere { radius } => b(Vec3::splat(-radius), Vec3::splat(*radius)),
            Shape::Plane => None,
            Shape::Disk { radius } => b(
                Vec3::new(-radius, 0.0, -radius),
                Vec3::new(*radius, 0.0, *radius),
            ),
            Shape::Polygon { vertices } => {
                let mut min = Vec3::splat(f32::INFINITY);
                let mut max = Vec3::splat(f32::NEG_INFINITY);
                for v in vertices.iter() {
                    min = min.min(*v);
                    max = max.max(*v);
                }
                b(min, max)
            }
            Shape::Cylinder {
                radius,
                y_min,
                y_max,
            } => b(
                Vec3::new(-radius, *y_min, -radius),
                Vec3::new(*radius, *y_max, *radius),
            ),
            Shape::Cone { radius, height } | Shape::Paraboloid { radius, height } => b(
                Vec3::new(-radius, 0.0, -radius),
                Vec3::new(*radius, *height, *radius),
            ),
            Shape::Ellipsoid { radii } => b(-*radii, *radii),
            Shape::Hyperboloid {
                top_radius,
                half_height,
                ..
            } => b(
                Vec3::new(-top_radius, -half_height, -top_radius),
                Vec3::new(*top_radius, *half_height, *top_radius),
            ),
        }
    }

    /// The closest intersection with parameter strictly inside
    /// `(t_min, t_max)`, if any.
    ///
    /// `ray` is in object space and its direction need not be unit length:
    /// `t` is the parameter along the direction as given. When the nearer
    /// root of a quadric is outside the interval or outside the shape's
    /// extent, the farther one is returned if it qualifies (rays starting
    /// inside a closed shape, or entering an open one through its end).
    ///
    /// The normal is the outward geometric normal in object space (not
    /// unit length, never flipped towards the ray). Texture coordinates:
    ///
    /// * sphere, ellipsoid: `(phi / 2pi, theta / pi)` where
    ///   `phi = atan2(z, x)` in `[0, 2pi)` and `theta` is the polar angle
    ///   from `+Y` (so `v = 0` at the top pole); for the ellipsoid both
    ///   angles are taken on the unit sphere `p / radii`;
    /// * plane: `(x, z)`;
    /// * disk: `(x / r, z / r) * 0.5 + 0.5`, the disk's bounding square
    ///   mapped to the unit square;
    /// * polygon: coordinates of the hit point (measured from the
    ///   object-space origin) along an orthonormal basis `(u, v)` of the
    ///   polygon's plane, where `u` is the normalised projection of `+X`
    ///   onto the plane (`+Z` when the normal is nearly parallel to `X`)
    ///   and `v = u x n`; a polygon in `y = 0` facing `+Y` gets `(x, z)`,
    ///   like the plane;
    /// * cylinder, cone, paraboloid, hyperboloid: `(phi / 2pi, h)` with
    ///   `phi = atan2(z, x)` in `[0, 2pi)` and `h` the height normalised to
    ///   `[0, 1]` over the extent (`(y - y_min) / (y_max - y_min)`, `y / height`,
    ///   `y / height`, `(y + half_height) / (2 half_height)` respectively).
    ///
    /// Returns `None` rather than a hit with a non-finite `t`, normal or
    /// `uv`.
    pub fn intersect(&self, ray: &Ray, t_min: f32, t_max: f32) -> Option<ShapeHit> {
        let hit = match self {
            Shape::Sphere { radius } => intersect_sphere(ray, *radius, t_min, t_max),
            Shape::Plane => intersect_plane(ray, t_min, t_max),
            Shape::Disk { radius } => intersect_disk(ray, *radius, t_min, t_max),
            Shape::Polygon { vertices } => intersect_polygon(ray, vertices, t_min, t_max),
            Shape::Cylinder {
                radius,
                y_min,
                y_max,
            } => intersect_cylinder(ray, *radius, *y_min, *y_max, t_min, t_max),
            Shape::Cone { radius, height } => {
                rebased(ray, 0.5 * height, t_min, t_max, |r, lo, hi| {
                    intersect_cone(r, *radius, *height, lo, hi)
                })
            }
            Shape::Ellipsoid { radii } => intersect_ellipsoid(ray, *radii, t_min, t_max),
            Shape::Paraboloid { radius, height } => {
                rebased(ray, 0.5 * height, t_min, t_max, |r, lo, hi| {
                    intersect_paraboloid(r, *radius, *height, lo, hi)
                })
            }
            Shape::Hyperboloid {
                waist_radius,
                top_radius,
                half_height,
            } => rebased(ray, 0.0, t_min, t_max, |r, lo, hi| {
                intersect_hyperboloid(r, *waist_radius, *top_radius, *half_height, lo, hi)
            }),
        }?;
        hit.is_finite().then_some(hit)
    }

    /// The `t` of [`Shape::intersect`]'s hit, if any: the same answer.
    /// The plane answers without building the hit (the other shapes call
    /// [`Shape::intersect`]).
    #[inline]
    pub fn intersect_t(&self, ray: &Ray, t_min: f32, t_max: f32) -> Option<f32> {
        match self {
            Shape::Plane => planar::plane_t(ray, t_min, t_max),
            _ => self.intersect(ray, t_min, t_max).map(|h| h.t),
        }
    }

    /// Whether [`Shape::intersect`] finds a hit: the same answer, for
    /// shadow rays. The plane and the disk answer without building the hit
    /// (which costs shadow rays of a scene with a ground plane a tenth of
    /// their instructions: every ray tests the unbounded plane); the other
    /// shapes call [`Shape::intersect`].
    #[inline]
    pub fn occludes(&self, ray: &Ray, t_min: f32, t_max: f32) -> bool {
        match self {
            Shape::Plane => planar::occludes_plane(ray, t_min, t_max),
            Shape::Disk { radius } => planar::occludes_disk(ray, *radius, t_min, t_max),
            _ => self.intersect(ray, t_min, t_max).is_some(),
        }
    }
}

#[cfg(test)]
mod tests;
