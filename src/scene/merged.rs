//! Mesh instances merged into one BVH: when every bounded instance of a
//! scene is a mesh of its own (a glTF file's), their triangles, placed in
//! the render frame, under one mesh BVH, so that a ray traverses one tree
//! instead of the top level and then one tree per instance it reaches
//! (each visit paying the ray's transformation to object space and its
//! watertight setup). See the README, "Merged mesh instances".
//!
//! The group is an acceleration structure only: a hit on it is mapped
//! back to the instance and triangle it came from
//! ([`MergedMeshes::owner`]) before anything else sees it, so shading,
//! emitters, texture lookups and every other user of
//! [`Hit::instance`](crate::scene::Hit::instance) see the scene as it
//! was. What changes is the arithmetic of the hit: the triangle is
//! intersected in the render frame (its corners transformed once, in
//! f32) instead of in object space (the ray transformed), so `t` and the
//! barycentrics may differ in their last bits from an unmerged scene's.
//!
//! Merging is opt-in ([`RenderScene::set_mesh_merging`](crate::scene::RenderScene::set_mesh_merging)):
//! it suits scenes that do not move (a still render, a benchmark), and
//! it is undone, never redone, by the first change that touches a member
//! (see `update.rs`), so a scene that moves pays for it once.

use std::sync::Arc;

use glam::{Vec3, Vec3A};

use crate::accel::build::BuildQuality;
use crate::core::settings::Accel;
use crate::geometry::mesh::{Mesh, MeshData, NormalMode};
use crate::geometry::transform::Transform;
use crate::scene::instance::{Instance, InstanceGeometry};

/// The instance index that partial hits carry while they are on the
/// merged group (before [`MergedMeshes::owner`] maps them back). Fits the
/// 29 bits that stream keys give an instance.
pub(crate) const MERGED: u32 = (1 << 29) - 1;

/// Fewest instances worth merging: a single instance keeps its own BVH.
const MIN_MEMBERS: usize = 2;

/// Most triangles merged; beyond it the copy's memory and build time are
/// not spent.
const MAX_TRIANGLES: usize = 1 << 24;

/// One BVH over the triangles of several mesh instances (see the module
/// documentation).
#[derive(Debug)]
pub(crate) struct MergedMeshes {
    /// The group as an instance: the merged mesh, placed with the identity
    /// (its corners are in the render frame already). Queries never
    /// transform rays into it.
    pub(crate) instance: Instance,
    /// For each triangle of the merged mesh (its BVH order): the instance
    /// it belongs to and its index in that instance's mesh (BVH order).
    owners: Vec<(u32, u32)>,
    /// For each triangle of the merged mesh: its owner's geometric normal
    /// in world space, as a hit on it computes it
    /// (`InstanceTransform::normal` of [`Mesh::geometric_normal`]), so
    /// that a hit reads it instead (the group is undone by any change to
    /// a member's placement or mesh).
    normals: Vec<Vec3A>,
    /// True for the instances merged, per instance index.
    member: Vec<bool>,
}

impl MergedMeshes {
    /// Merges the scene's instances, or returns `None` unless every
    /// bounded instance can be merged and there are at least two. An
    /// instance can when it is a mesh with a BVH, bounded, not cut away by
    /// its material (`cut_out(i)`), and the only instance of its mesh
    /// (instanced meshes stay instanced: merging would copy them).
    pub(crate) fn build(
        instances: &[Instance],
        cut_out: impl Fn(&Instance) -> bool,
        quality: BuildQuality,
    ) -> Option<Self> {
        let mut uses = std::collections::HashMap::<*const Mesh, u32>::new();
        for inst in instances {
            if let InstanceGeometry::Mesh(m) = &inst.geometry {
                *uses.entry(Arc::as_ptr(m)).or_default() += 1;
            }
        }
        let mut member = vec![false; instances.len()];
        let mut members = Vec::new();
        let mut triangles = 0usize;
        for (i, inst) in instances.iter().enumerate() {
            let InstanceGeometry::Mesh(m) = &inst.geometry else {
                continue;
            };
            if m.accel() != Accel::Bvh
                || uses[&Arc::as_ptr(m)] != 1
                || inst.world_bounds().is_none()
                || cut_out(inst)
                || triangles + m.triangle_count() > MAX_TRIANGLES
            {
                continue;
            }
            triangles += m.triangle_count();
            member[i] = true;
            members.push((i as u32, m));
        }
        // Only a group that empties the top level of bounded instances:
        // a ray then makes one traversal. Beside a top level that keeps
        // other instances, every ray would make two, and the group's box
        // spans all its members wherever they are (a scene of 8 merged
        // meshes among 26 instances, `assets/bench/many_lights.toml`,
        // rendered 10-20% slower).
        let bounded = instances
            .iter()
            .filter(|i| i.world_bounds().is_some())
            .count();
        if members.len() < MIN_MEMBERS || members.len() < bounded {
            return None;
        }
        // The input: every member's triangles in input order, member
        // after member; `source[j]` = (instance, triangle in BVH order of
        // its mesh) of input triangle `j`.
        let mut data = MeshData::default();
        let mut source = Vec::with_capacity(triangles);
        for (i, m) in &members {
            let to_world = &instances[*i as usize].transform.to_world;
            let base = data.positions.len() as u32;
            data.positions.extend(
                m.positions()
                    .iter()
                    .map(|&p| Vec3::from(to_world.transform_point3a(p))),
            );
            let mut bvh_index = vec![0u32; m.triangle_count()];
            for k in 0..m.triangle_count() {
                bvh_index[m.input_triangle(k) as usize] = k as u32;
            }
            for (j, tri) in m.input_indices().into_iter().enumerate() {
                data.indices.push(tri.map(|v| v + base));
                source.push((*i, bvh_index[j]));
            }
        }
        // Corners transformed by a valid placement stay finite; the
        // instances' bounds were checked against the builder's range.
        let mesh = Mesh::new("merged instances", data, NormalMode::Flat, quality).ok()?;
        let owners: Vec<(u32, u32)> = (0..mesh.triangle_count())
            .map(|b| source[mesh.input_triangle(b) as usize])
            .collect();
        let normals = owners
            .iter()
            .map(|&(i, t)| {
                let inst = &instances[i as usize];
                let InstanceGeometry::Mesh(m) = &inst.geometry else {
                    unreachable!("members are meshes")
                };
                inst.transform.normal(m.geometric_normal(t))
            })
            .collect();
        Some(Self {
            instance: Instance::new(
                InstanceGeometry::Mesh(Arc::new(mesh)),
                &Transform::default(),
                0,
            ),
            owners,
            normals,
            member,
        })
    }

    /// The merged mesh.
    #[inline(always)]
    pub(crate) fn mesh(&self) -> &Mesh {
        match &self.instance.geometry {
            InstanceGeometry::Mesh(m) => m,
            InstanceGeometry::Shape(_) => unreachable!("the group is a mesh"),
        }
    }

    /// The instance and its mesh's triangle (BVH order) of triangle
    /// `triangle` (BVH order) of the merged mesh.
    #[inline(always)]
    pub(crate) fn owner(&self, triangle: u32) -> (u32, u32) {
        self.owners[triangle as usize]
    }

    /// The world geometric normal of a hit on triangle `triangle` (BVH
    /// order) of the merged mesh (see [`MergedMeshes::normals`]).
    #[inline(always)]
    pub(crate) fn normal(&self, triangle: u32) -> Vec3A {
        self.normals[triangle as usize]
    }

    /// True when instance `index` is merged.
    #[inline(always)]
    pub(crate) fn is_member(&self, index: u32) -> bool {
        self.member.get(index as usize).copied().unwrap_or(false)
    }

    /// The instances merged, in index order.
    pub(crate) fn members(&self) -> impl Iterator<Item = u32> + '_ {
        self.member
            .iter()
            .enumerate()
            .filter(|(_, m)| **m)
            .map(|(i, _)| i as u32)
    }

    /// Number of instances merged.
    pub(crate) fn member_count(&self) -> usize {
        self.member.iter().filter(|&&m| m).count()
    }

    /// Records that an instance was appended (it is not merged).
    pub(crate) fn pushed(&mut self) {
        self.member.push(false);
    }

    /// Records that instance `index`, not merged, was swap-removed, the
    /// last instance taking its index; the caller has checked that the
    /// last is not merged either (else the group is undone first).
    pub(crate) fn swap_removed(&mut self, index: u32) {
        self.member.swap_remove(index as usize);
    }

    /// Bytes of the merged copy (triangles, BVH, owners, normals).
    pub(crate) fn bytes(&self) -> usize {
        self.mesh().accel_bytes()
            + self.owners.len() * std::mem::size_of::<(u32, u32)>()
            + self.normals.len() * std::mem::size_of::<Vec3A>()
    }
}
