//! Emissive surfaces as area lights: the table path tracing samples for
//! next-event estimation, and the densities multiple importance sampling
//! needs when a scattered ray hits an emitter instead.
//!
//! Every emissive mesh triangle, polygon (split into a fan), disk and
//! sphere is an entry. Entries are chosen in proportion to their power
//! (area times the luminance of the material's emission factor), then a
//! point is drawn uniformly over the entry's area. Emission is two-sided,
//! as the shading kernels see it.
//!
//! Other emissive shapes (planes, cylinders, cones, quadrics) and emissive
//! spheres or disks whose emission is textured still glow, but only rays
//! that hit them find them: their light density here is zero, which keeps
//! the combined estimator unbiased.

use glam::{Vec2, Vec3A};

use crate::core::math::{Color, luminance};
use crate::geometry::mesh::MeshHit;
use crate::geometry::shapes::Shape;
use crate::geometry::transform::InstanceTransform;
use crate::scene::instance::{Instance, InstanceGeometry};
use crate::scene::material::Material;

/// A point drawn on an emitter.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EmitterSample {
    /// World-space point on the surface.
    pub point: Vec3A,
    /// Unit world-space geometric normal there (either side may emit).
    pub normal: Vec3A,
    /// Emitted radiance at the point.
    pub radiance: Color,
    /// Density of having drawn this point, per unit world area, selection
    /// of the entry included.
    pub pdf_area: f32,
}

#[derive(Clone, Copy, Debug)]
enum EntryGeometry {
    /// A world-space triangle `p0 + b1 e1 + b2 e2`; `triangle` is the
    /// mesh triangle (for texture coordinates) or `u32::MAX` for a
    /// polygon's fan triangle.
    Triangle {
        p0: Vec3A,
        e1: Vec3A,
        e2: Vec3A,
        normal: Vec3A,
        triangle: u32,
    },
    /// Two triangles of one instance that make the parallelogram `p0 + s
    /// e1 + t e2` (`s`, `t` in `[0, 1]`; a quad light), sampled as one:
    /// the sample's two numbers cover it as a unit square, keeping their
    /// stratification, where choosing a triangle and folding its
    /// barycentrics scattered it. The same density as the two triangles.
    Parallelogram {
        p0: Vec3A,
        e1: Vec3A,
        e2: Vec3A,
        normal: Vec3A,
    },
    /// A sphere of `radius` in object space; world area density varies
    /// with the transform's stretch at each point.
    Sphere { radius: f32 },
    /// A disk of `radius` in the object's `y = 0` plane.
    Disk { radius: f32, world_area: f32 },
}

#[derive(Clone, Copy, Debug)]
struct Entry {
    instance: u32,
    geometry: EntryGeometry,
}

/// How an instance's points are weighted, to answer density queries.
#[derive(Clone, Copy, Debug, Default)]
enum InstanceDensity {
    /// Not sampled as a light.
    #[default]
    None,
    /// Triangles and polygons: selection probability per unit area, the
    /// same over the whole instance.
    Uniform(f32),
    /// A sphere: selection probability of the entry, spread over its
    /// object-space area `4 pi r^2` and stretched by the transform.
    Sphere { select: f32, radius: f32 },
}

/// The emitters of a scene, ready for sampling.
#[derive(Clone, Debug, Default)]
pub struct EmitterTable {
    entries: Vec<Entry>,
    /// Cumulative selection probabilities; the last is exactly 1.
    cdf: Vec<f32>,
    /// Per instance, how to evaluate light densities on it.
    density: Vec<InstanceDensity>,
    /// Sum over entries of area times emission weight (the selection
    /// weights' total).
    weighted_area: f32,
}

/// Luminance of the emission factor used to weight an emitter.
fn emission_weight(m: &Material) -> f32 {
    let l = luminance(m.emission);
    if l.is_finite() && l > 0.0 { l } else { 0.0 }
}

/// Area scale `|det M| |M^-T n|` of the linear map at unit object normal `n`.
#[inline]
fn area_stretch(xf: &InstanceTransform, n: Vec3A) -> f32 {
    xf.to_world.matrix3.determinant().abs() * (xf.normal_to_world * n).length()
}

impl EmitterTable {
    /// Collects the emitters among `instances`.
    pub fn build(instances: &[Instance], materials: &[Material]) -> Self {
        let mut entries = Vec::new();
        let mut power = Vec::new();
        let mut density = vec![InstanceDensity::None; instances.len()];
        // First pass: entries with their power; densities are fixed once
        // the total is known.
        // (instance, emission weight, its first entry)
        let mut per_instance: Vec<(usize, f32, usize)> = Vec::new();
        for (i, inst) in instances.iter().enumerate() {
            let Some(m) = materials.get(inst.material as usize) else {
                continue;
            };
            let weight = emission_weight(m);
            if weight == 0.0 {
                continue;
            }
            let xf = &inst.transform;
            let first = entries.len();
            // World-space triangles of a mesh or polygon, with their mesh
            // triangle (`u32::MAX` for a polygon's fan).
            let mut triangles: Vec<([Vec3A; 3], u32)> = Vec::new();
            let mut world = |a: Vec3A, b: Vec3A, c: Vec3A, triangle: u32| {
                triangles.push((
                    [
                        xf.to_world.transform_point3a(a),
                        xf.to_world.transform_point3a(b),
                        xf.to_world.transform_point3a(c),
                    ],
                    triangle,
                ));
            };
            match &inst.geometry {
                InstanceGeometry::Mesh(mesh) => {
                    for t in 0..mesh.triangle_count() {
                        let [a, b, c] = mesh.triangle(t);
                        world(a, b, c, t as u32);
                    }
                }
                InstanceGeometry::Shape(Shape::Polygon { vertices }) => {
                    let v0 = Vec3A::from(vertices[0]);
                    for k in 1..vertices.len() - 1 {
                        let (b, c) = (Vec3A::from(vertices[k]), Vec3A::from(vertices[k + 1]));
                        world(v0, b, c, u32::MAX);
                    }
                }
                InstanceGeometry::Shape(Shape::Sphere { radius })
                    if m.emission_texture.is_none() =>
                {
                    // Selection weight from the area at the three axes'
                    // stretch (exact for uniform scale; only a weight).
                    let stretch = (area_stretch(xf, Vec3A::X)
                        + area_stretch(xf, Vec3A::Y)
                        + area_stretch(xf, Vec3A::Z))
                        / 3.0;
                    let area = 4.0 * std::f32::consts::PI * radius * radius * stretch;
                    if area.is_finite() && area > 0.0 {
                        entries.push(Entry {
                            instance: i as u32,
                            geometry: EntryGeometry::Sphere { radius: *radius },
                        });
                        power.push(area * weight);
                    }
                }
                InstanceGeometry::Shape(Shape::Disk { radius }) if m.emission_texture.is_none() => {
                    let world_area =
                        std::f32::consts::PI * radius * radius * area_stretch(xf, Vec3A::Y);
                    if world_area.is_finite() && world_area > 0.0 {
                        entries.push(Entry {
                            instance: i as u32,
                            geometry: EntryGeometry::Disk {
                                radius: *radius,
                                world_area,
                            },
                        });
                        power.push(world_area * weight);
                    }
                }
                InstanceGeometry::Shape(_) => {}
            }
            // Neighbouring triangles that make a parallelogram are one
            // entry, unless a texture needs each point's triangle.
            let textured = m.emission_texture.is_some();
            let mut k = 0;
            while k < triangles.len() {
                let (t, triangle) = triangles[k];
                let pair = triangles.get(k + 1).filter(|_| !textured);
                if let Some((p0, e1, e2)) = pair.and_then(|(u, _)| parallelogram(&t, u)) {
                    let cross = e1.cross(e2);
                    let area = cross.length();
                    if area.is_finite() && area > 0.0 {
                        entries.push(Entry {
                            instance: i as u32,
                            geometry: EntryGeometry::Parallelogram {
                                p0,
                                e1,
                                e2,
                                normal: cross / area,
                            },
                        });
                        power.push(area * weight);
                        k += 2;
                        continue;
                    }
                }
                let [p0, p1, p2] = t;
                let cross = (p1 - p0).cross(p2 - p0);
                let area = 0.5 * cross.length();
                if area.is_finite() && area > 0.0 {
                    entries.push(Entry {
                        instance: i as u32,
                        geometry: EntryGeometry::Triangle {
                            p0,
                            e1: p1 - p0,
                            e2: p2 - p0,
                            normal: cross / (2.0 * area),
                            triangle,
                        },
                    });
                    power.push(area * weight);
                }
                k += 1;
            }
            if entries.len() > first {
                per_instance.push((i, weight, first));
            }
        }
        let total: f64 = power.iter().map(|&p| p as f64).sum();
        if !(total > 0.0 && total.is_finite()) {
            return Self {
                density,
                ..Default::default()
            };
        }
        let mut acc = 0.0f64;
        let mut cdf: Vec<f32> = power
            .iter()
            .map(|&p| {
                acc += p as f64;
                (acc / total) as f32
            })
            .collect();
        if let Some(last) = cdf.last_mut() {
            *last = 1.0;
        }
        for (i, weight, k) in per_instance {
            density[i] = match &instances[i].geometry {
                // One entry per sphere or disk, at `k`.
                InstanceGeometry::Shape(Shape::Sphere { radius }) => InstanceDensity::Sphere {
                    select: (power[k] as f64 / total) as f32,
                    radius: *radius,
                },
                InstanceGeometry::Shape(Shape::Disk { .. }) => {
                    // Uniform over the disk: selection over world area.
                    let EntryGeometry::Disk { world_area, .. } = entries[k].geometry else {
                        unreachable!("disk entry")
                    };
                    InstanceDensity::Uniform((power[k] as f64 / total) as f32 / world_area)
                }
                // Triangles: power = area * weight, so the selection
                // probability per unit area is weight / total everywhere.
                _ => InstanceDensity::Uniform((weight as f64 / total) as f32),
            };
        }
        Self {
            entries,
            cdf,
            density,
            weighted_area: total as f32,
        }
    }

    /// Sum over the entries of their world area times the luminance of
    /// their material's emission factor: the emitted power per unit
    /// radiance-steradian, so that `2 pi` times it is the total power of
    /// the table's (two-sided, untextured) emitters in luminance.
    pub fn weighted_area(&self) -> f32 {
        self.weighted_area
    }

    /// True when there is nothing to sample.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// Number of entries (triangles, fan triangles, disks, spheres).
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// Draws a point: `u` chooses the entry, `v` the point on it. `None`
    /// when the table is empty or the point's emission is zero.
    pub fn sample(
        &self,
        instances: &[Instance],
        materials: &[Material],
        u: f32,
        v: Vec2,
    ) -> Option<EmitterSample> {
        if self.entries.is_empty() {
            return None;
        }
        let k = self
            .cdf
            .partition_point(|&c| c <= u)
            .min(self.entries.len() - 1);
        let entry = &self.entries[k];
        let inst = &instances[entry.instance as usize];
        let material = &materials[inst.material as usize];
        let xf = &inst.transform;
        let (point, normal, uv) = match entry.geometry {
            EntryGeometry::Triangle {
                p0,
                e1,
                e2,
                normal,
                triangle,
                ..
            } => {
                // Uniform barycentrics by folding the unit square.
                let (mut b1, mut b2) = (v.x, v.y);
                if b1 + b2 > 1.0 {
                    b1 = 1.0 - b1;
                    b2 = 1.0 - b2;
                }
                let point = p0 + e1 * b1 + e2 * b2;
                let uv = if material.emission_texture.is_none() {
                    Vec2::ZERO
                } else {
                    match &inst.geometry {
                        InstanceGeometry::Mesh(mesh) if triangle != u32::MAX => {
                            mesh.surface(&MeshHit {
                                t: 0.0,
                                triangle,
                                b1,
                                b2,
                            })
                            .uv
                        }
                        InstanceGeometry::Shape(shape) => {
                            shape_uv(shape, xf.to_object.transform_point3a(point))
                        }
                        InstanceGeometry::Mesh(_) => Vec2::ZERO,
                    }
                };
                (point, normal, uv)
            }
            EntryGeometry::Parallelogram { p0, e1, e2, normal } => {
                (p0 + e1 * v.x + e2 * v.y, normal, Vec2::ZERO)
            }
            EntryGeometry::Sphere { radius } => {
                let n_o = crate::core::sampling::uniform_sphere(v);
                let point = xf.to_world.transform_point3a(n_o * radius);
                (point, xf.normal(n_o), Vec2::ZERO)
            }
            EntryGeometry::Disk { radius, .. } => {
                let d = crate::core::sampling::concentric_disk(v) * radius;
                let point = xf.to_world.transform_point3a(Vec3A::new(d.x, 0.0, d.y));
                (point, xf.normal(Vec3A::Y), Vec2::ZERO)
            }
        };
        let pdf_area = self.pdf_area(instances, entry.instance, point);
        let radiance = material.emission_at(uv);
        (pdf_area > 0.0 && radiance.max_element() > 0.0 && point.is_finite()).then_some(
            EmitterSample {
                point,
                normal,
                radiance,
                pdf_area,
            },
        )
    }

    /// Density per unit world area with which [`EmitterTable::sample`]
    /// draws `point`, a point on instance `instance`; zero for instances
    /// that are not sampled.
    pub fn pdf_area(&self, instances: &[Instance], instance: u32, point: Vec3A) -> f32 {
        match self.density.get(instance as usize) {
            None | Some(InstanceDensity::None) => 0.0,
            Some(InstanceDensity::Uniform(p)) => *p,
            Some(InstanceDensity::Sphere { select, radius }) => {
                let xf = &instances[instance as usize].transform;
                let n_o = xf.to_object.transform_point3a(point).normalize_or_zero();
                let stretch = area_stretch(xf, n_o);
                let area_o = 4.0 * std::f32::consts::PI * radius * radius;
                if stretch > 0.0 {
                    select / (area_o * stretch)
                } else {
                    0.0
                }
            }
        }
    }
}

/// The parallelogram `(p0, e1, e2)` that triangles `a` and `b` make
/// together, if they do: they share two corners exactly (a diagonal), and
/// their other corners `q_a`, `q_b` are opposite, `q_a + q_b` equal to the
/// diagonal's sum within `1e-5` of its length (the diagonals bisect each
/// other). Then `p0 = q_a` and the edges run to the diagonal's ends; the
/// fourth corner is `q_b` within that tolerance.
fn parallelogram(a: &[Vec3A; 3], b: &[Vec3A; 3]) -> Option<(Vec3A, Vec3A, Vec3A)> {
    // The corner of `a` that `b` lacks, and the two it shares.
    let lone = (0..3).find(|&k| !b.contains(&a[k]))?;
    let (s0, s1) = match lone {
        0 => (a[1], a[2]),
        1 => (a[0], a[2]),
        _ => (a[0], a[1]),
    };
    if !(b.contains(&s0) && b.contains(&s1)) {
        return None;
    }
    let qa = a[lone];
    let qb = *b.iter().find(|&&p| p != s0 && p != s1)?;
    let diagonal = (s1 - s0).length();
    let off = (qa + qb - (s0 + s1)).length();
    (diagonal > 0.0 && off <= 1e-5 * diagonal).then_some((qa, s0 - qa, s1 - qa))
}

/// Texture coordinates of a point on a polygon, as its intersection
/// routine gives them.
fn shape_uv(shape: &Shape, p: Vec3A) -> Vec2 {
    match shape {
        Shape::Polygon { vertices } => {
            let n = crate::geometry::shapes::polygon_normal(vertices).normalize();
            let n = Vec3A::from(n);
            let reference = if n.x.abs() < 0.9 { Vec3A::X } else { Vec3A::Z };
            let u_axis = (reference - n * n.dot(reference)).normalize();
            let v_axis = u_axis.cross(n);
            Vec2::new(p.dot(u_axis), p.dot(v_axis))
        }
        _ => Vec2::ZERO,
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use glam::{Quat, Vec3};

    use super::*;
    use crate::core::rng::Sampler;
    use crate::geometry::transform::Transform;

    fn glowing(e: f32) -> Material {
        Material {
            emission: Color::splat(e),
            ..Default::default()
        }
    }

    /// A rectangle light is one entry whose two sample numbers cover it as
    /// a unit square: the centres of a 4x4 grid of numbers land one in
    /// each cell of the rectangle's 4x4 grid, at the same density as the
    /// two triangles. A trapezoid stays two triangles.
    #[test]
    fn quads_are_sampled_as_parallelograms() {
        let polygon = |v: [Vec3; 4]| Shape::Polygon {
            vertices: Arc::from(v.to_vec()),
        };
        let xf = Transform::from_trs_f32(
            Vec3::new(0.5, 2.0, -1.0),
            Quat::from_rotation_z(0.4),
            Vec3::ONE,
        );
        let rect = polygon([
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(2.0, 0.0, 0.0),
            Vec3::new(2.0, 0.0, 1.0),
            Vec3::new(0.0, 0.0, 1.0),
        ]);
        let instances = vec![Instance::new(InstanceGeometry::Shape(rect), &xf, 0)];
        let materials = vec![glowing(3.0)];
        let table = EmitterTable::build(&instances, &materials);
        assert_eq!(table.len(), 1);
        let mut cells = [0u32; 16];
        for i in 0..4 {
            for j in 0..4 {
                let v = Vec2::new((i as f32 + 0.5) / 4.0, (j as f32 + 0.5) / 4.0);
                let es = table.sample(&instances, &materials, 0.3, v).unwrap();
                assert!((es.pdf_area - 0.5).abs() < 1e-6, "{}", es.pdf_area);
                let p = instances[0].transform.to_object.transform_point3a(es.point);
                assert!(p.y.abs() < 1e-5, "{p}");
                let (x, z) = ((p.x * 2.0) as usize, (p.z * 4.0) as usize);
                cells[x.min(3) * 4 + z.min(3)] += 1;
            }
        }
        assert_eq!(cells, [1; 16]);
        let trapezoid = polygon([
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(2.0, 0.0, 0.0),
            Vec3::new(1.5, 0.0, 1.0),
            Vec3::new(0.5, 0.0, 1.0),
        ]);
        let instances = vec![Instance::new(InstanceGeometry::Shape(trapezoid), &xf, 0)];
        assert_eq!(EmitterTable::build(&instances, &materials).len(), 2);
    }

    /// Area of the ellipsoid with semi-axes `a`, by midpoint quadrature
    /// of `|dp/dtheta x dp/dphi|` over a fine grid.
    fn ellipsoid_area(a: Vec3) -> f64 {
        let (nt, np) = (600, 1200);
        let (dt, dp) = (
            std::f64::consts::PI / nt as f64,
            2.0 * std::f64::consts::PI / np as f64,
        );
        let (ax, ay, az) = (a.x as f64, a.y as f64, a.z as f64);
        let mut sum = 0.0;
        for i in 0..nt {
            let t = (i as f64 + 0.5) * dt;
            for j in 0..np {
                let p = (j as f64 + 0.5) * dp;
                let dtv = [
                    ax * t.cos() * p.cos(),
                    ay * t.cos() * p.sin(),
                    -az * t.sin(),
                ];
                let dpv = [-ax * t.sin() * p.sin(), ay * t.sin() * p.cos(), 0.0];
                let c = [
                    dtv[1] * dpv[2] - dtv[2] * dpv[1],
                    dtv[2] * dpv[0] - dtv[0] * dpv[2],
                    dtv[0] * dpv[1] - dtv[1] * dpv[0],
                ];
                sum += (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt() * dt * dp;
            }
        }
        sum
    }

    /// `E[1 / pdf_area]` over the table's own samples is the total
    /// emitting area: a check of every density, selection included.
    #[test]
    fn inverse_densities_average_to_the_emitting_area() {
        let square = Shape::Polygon {
            vertices: Arc::from(vec![
                Vec3::new(0.0, 0.0, 0.0),
                Vec3::new(2.0, 0.0, 0.0),
                Vec3::new(2.0, 0.0, 1.0),
                Vec3::new(0.0, 0.0, 1.0),
            ]),
        };
        let stretch = Vec3::new(1.5, 0.7, 0.4);
        let instances = vec![
            // Not emissive: never sampled.
            Instance::new(
                InstanceGeometry::Shape(Shape::Sphere { radius: 1.0 }),
                &Transform::default(),
                0,
            ),
            Instance::new(
                InstanceGeometry::Shape(square),
                &Transform::from_trs_f32(
                    Vec3::new(0.0, 3.0, 0.0),
                    Quat::from_rotation_x(0.3),
                    Vec3::ONE,
                ),
                1,
            ),
            Instance::new(
                InstanceGeometry::Shape(Shape::Disk { radius: 0.5 }),
                &Transform::from_trs_f32(
                    Vec3::new(4.0, 1.0, 0.0),
                    Quat::IDENTITY,
                    Vec3::new(2.0, 1.0, 3.0),
                ),
                2,
            ),
            Instance::new(
                InstanceGeometry::Shape(Shape::Sphere { radius: 0.8 }),
                &Transform::from_trs_f32(
                    Vec3::new(-3.0, 1.0, 0.0),
                    Quat::from_rotation_y(0.7),
                    stretch,
                ),
                1,
            ),
        ];
        let materials = vec![Material::default(), glowing(2.0), glowing(5.0)];
        let table = EmitterTable::build(&instances, &materials);
        // The square is one parallelogram entry.
        assert_eq!(table.len(), 1 + 1 + 1);
        let pi = std::f64::consts::PI;
        let area = 2.0 + pi * 0.25 * 6.0 + ellipsoid_area(stretch * 0.8);
        let n = 200_000;
        let (mut sum, mut sum2) = (0.0f64, 0.0f64);
        for i in 0..n {
            let mut s = Sampler::new(1, i, 0);
            let u = s.next_f32();
            let v = Vec2::new(s.next_f32(), s.next_f32());
            let es = table.sample(&instances, &materials, u, v).unwrap();
            assert!((es.normal.length() - 1.0).abs() < 1e-4);
            let x = 1.0 / es.pdf_area as f64;
            sum += x;
            sum2 += x * x;
        }
        let mean = sum / n as f64;
        let err = ((sum2 / n as f64 - mean * mean) / n as f64).sqrt();
        assert!(
            (mean - area).abs() < 5.0 * err + 1e-4 * area,
            "mean 1/pdf {mean} vs area {area} (standard error {err})"
        );
        // Densities answered for hit points agree with the sampled ones.
        assert_eq!(table.pdf_area(&instances, 0, Vec3A::ZERO), 0.0);
    }
}
