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

use crate::math::Ray;

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
    /// Outward geometric normal in object space (not necessarily unit).
    pub normal: Vec3A,
    /// Surface parameterisation, used for textures.
    pub uv: Vec2,
}

fn positive(name: &str, v: f32) -> Result<(), String> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(format!("{name} must be a positive finite number, got {v}"))
    }
}

impl Shape {
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

    /// The closest intersection with parameter in `(t_min, t_max)`, if any.
    pub fn intersect(&self, ray: &Ray, t_min: f32, t_max: f32) -> Option<ShapeHit> {
        let _ = (ray, t_min, t_max);
        None
    }
}

/// Newell normal of a polygon (unnormalised; length is twice the area).
pub fn polygon_normal(vertices: &[Vec3]) -> Vec3 {
    let mut n = Vec3::ZERO;
    for (i, a) in vertices.iter().enumerate() {
        let b = vertices[(i + 1) % vertices.len()];
        n += Vec3::new(
            (a.y - b.y) * (a.z + b.z),
            (a.z - b.z) * (a.x + b.x),
            (a.x - b.x) * (a.y + b.y),
        );
    }
    n
}

fn validate_polygon(vertices: &[Vec3]) -> Result<(), String> {
    if vertices.len() < 3 {
        return Err(format!(
            "polygon needs at least 3 vertices, got {}",
            vertices.len()
        ));
    }
    if vertices.iter().any(|v| !v.is_finite()) {
        return Err("polygon vertices must be finite".into());
    }
    let n = polygon_normal(vertices);
    let extent = vertices
        .iter()
        .map(|v| v.abs().max_element())
        .fold(0.0f32, f32::max);
    if !(n.length() > 1e-6 * extent * extent) {
        return Err("polygon has zero area".into());
    }
    let n = n.normalize();
    let scale = extent.max(1e-30);
    for v in vertices {
        if (n.dot(*v - vertices[0])).abs() > 1e-4 * scale {
            return Err("polygon vertices are not coplanar".into());
        }
    }
    for i in 0..vertices.len() {
        let a = vertices[i];
        let b = vertices[(i + 1) % vertices.len()];
        let c = vertices[(i + 2) % vertices.len()];
        if (b - a).cross(c - b).dot(n) < -1e-6 * scale * scale {
            return Err("polygon is not convex (or its vertices are not in order)".into());
        }
    }
    Ok(())
}
