//! The TF tree: static edges (from `/tf_static` or transforms that never change) and dynamic
//! edges (time series), with lookups `target_from_source` across chains.
//!
//! Frames are compared without a leading `/`. Static lookups walk both frames up to the root of
//! the static forest and meet at the common ancestor. The trajectory is the dynamic chain from a
//! fixed frame to the vehicle frame, sampled at the stamps of its densest edge.

use std::collections::BTreeMap;

use super::types::TransformMsg;
use crate::geometry::{Rigid, StampConflict, Trajectory, conflicting_stamps};

/// Names of world-fixed frames (REP 105 and common variants).
const FIXED_FRAMES: [&str; 4] = ["world", "map", "odom", "earth"];

pub fn normalize_frame(frame: &str) -> String {
    frame.trim_start_matches('/').to_string()
}

#[derive(Clone, Debug, Default)]
pub struct TfTree {
    /// child → (parent, parent_from_child)
    pub static_edges: BTreeMap<String, (String, Rigid)>,
    /// (parent, child) → time series of parent_from_child
    pub dynamic_edges: BTreeMap<(String, String), Vec<(i64, Rigid)>>,
}

impl TfTree {
    pub fn add_static(&mut self, t: &TransformMsg) {
        self.static_edges.insert(
            normalize_frame(&t.child),
            (normalize_frame(&t.parent), t.parent_from_child),
        );
    }

    pub fn add_dynamic(&mut self, t: &TransformMsg) {
        self.dynamic_edges
            .entry((normalize_frame(&t.parent), normalize_frame(&t.child)))
            .or_default()
            .push((t.stamp_nanos, t.parent_from_child));
    }

    /// Dynamic edges whose value never changes (or that were sent once) are moved to the static
    /// set: some recorders publish mounts on /tf. Edges from a fixed frame (world, map, odom,
    /// earth) to a non-fixed frame sent more than once stay dynamic: that is a stationary
    /// vehicle's trajectory.
    pub fn promote_constant_dynamic_edges(&mut self) {
        let constant: Vec<(String, String)> = self
            .dynamic_edges
            .iter()
            .filter(|((parent, child), series)| {
                !(series.len() > 1
                    && FIXED_FRAMES.contains(&parent.as_str())
                    && !FIXED_FRAMES.contains(&child.as_str()))
            })
            .filter(|(_, series)| {
                series.windows(2).all(|w| {
                    let (r, t) = w[0].1.difference(w[1].1);
                    r < 1e-9 && t < 1e-9
                })
            })
            .map(|(k, _)| k.clone())
            .collect();
        for key in constant {
            if let Some(series) = self.dynamic_edges.remove(&key)
                && let Some((_, t)) = series.first()
            {
                self.static_edges.insert(key.1.clone(), (key.0.clone(), *t));
            }
        }
    }

    /// `root_from_frame` up the static forest, and the root's name.
    fn to_static_root(&self, frame: &str) -> (String, Rigid) {
        let mut current = normalize_frame(frame);
        let mut root_from_frame = Rigid::IDENTITY;
        for _ in 0..self.static_edges.len() + 1 {
            match self.static_edges.get(&current) {
                Some((parent, parent_from_child)) => {
                    root_from_frame = *parent_from_child * root_from_frame;
                    current = parent.clone();
                }
                None => break,
            }
        }
        (current, root_from_frame)
    }

    /// `target_from_source` through static edges, if both lie in one static tree.
    pub fn static_transform(&self, target: &str, source: &str) -> Option<Rigid> {
        let (root_t, root_from_target) = self.to_static_root(target);
        let (root_s, root_from_source) = self.to_static_root(source);
        (root_t == root_s).then(|| root_from_target.inverse() * root_from_source)
    }

    /// Every frame named by any edge.
    pub fn frames(&self) -> Vec<String> {
        let mut f: Vec<String> = self
            .static_edges
            .iter()
            .flat_map(|(c, (p, _))| [c.clone(), p.clone()])
            .chain(
                self.dynamic_edges
                    .keys()
                    .flat_map(|(p, c)| [p.clone(), c.clone()]),
            )
            .collect();
        f.sort();
        f.dedup();
        f
    }

    /// For each dynamic edge whose series gives one stamp poses that disagree: the edge
    /// (parent, child) and its conflicts ([`crate::geometry::conflicting_stamps`]).
    pub fn conflicting_stamps(&self) -> Vec<((String, String), Vec<StampConflict>)> {
        self.dynamic_edges
            .iter()
            .map(|(edge, series)| (edge.clone(), conflicting_stamps(series)))
            .filter(|(_, conflicts)| !conflicts.is_empty())
            .collect()
    }

    /// The dynamic edge with the most samples: (fixed frame, vehicle frame).
    pub fn default_trajectory_frames(&self) -> Option<(String, String)> {
        self.dynamic_edges
            .iter()
            .max_by_key(|(_, s)| s.len())
            .map(|(k, _)| k.clone())
    }

    /// `world_from_vehicle(t)` for a dynamic chain `fixed → … → vehicle` (dynamic edges, possibly
    /// joined by static ones), sampled at the stamps of the densest dynamic edge in the chain.
    pub fn trajectory(&self, fixed: &str, vehicle: &str) -> Option<Trajectory> {
        let fixed = normalize_frame(fixed);
        let vehicle = normalize_frame(vehicle);
        // Walk from the vehicle up to the fixed frame, collecting edges (child → parent).
        enum Edge<'a> {
            Static(Rigid),
            Dynamic(&'a Trajectory),
        }
        let dynamic: BTreeMap<&(String, String), Trajectory> = self
            .dynamic_edges
            .iter()
            .map(|(k, s)| (k, Trajectory::new(s.clone())))
            .collect();
        let mut chain: Vec<Edge<'_>> = Vec::new();
        let mut current = vehicle.clone();
        let mut densest: Option<&Trajectory> = None;
        for _ in 0..self.static_edges.len() + self.dynamic_edges.len() + 1 {
            if current == fixed {
                break;
            }
            if let Some((key, traj)) = dynamic.iter().find(|(k, _)| k.1 == current) {
                if densest.is_none_or(|d| traj.len() > d.len()) {
                    densest = Some(traj);
                }
                chain.push(Edge::Dynamic(traj));
                current = key.0.clone();
            } else if let Some((parent, t)) = self.static_edges.get(&current) {
                chain.push(Edge::Static(*t));
                current = parent.clone();
            } else {
                return None;
            }
        }
        if current != fixed {
            return None;
        }
        let densest = densest?;
        let mut poses = Vec::with_capacity(densest.len());
        'stamps: for &stamp in densest.stamps_nanos() {
            let mut fixed_from_vehicle = Rigid::IDENTITY;
            for edge in chain.iter().rev() {
                let t = match edge {
                    Edge::Static(t) => *t,
                    Edge::Dynamic(traj) => match traj.world_from_vehicle(stamp) {
                        Ok(t) => t,
                        Err(_) => continue 'stamps,
                    },
                };
                fixed_from_vehicle = fixed_from_vehicle * t;
            }
            poses.push((stamp, fixed_from_vehicle));
        }
        Some(Trajectory::new(poses))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{DQuat, DVec3};

    fn edge(parent: &str, child: &str, t: Rigid) -> TransformMsg {
        TransformMsg {
            stamp_nanos: 0,
            parent: parent.into(),
            child: child.into(),
            parent_from_child: t,
        }
    }

    #[test]
    fn composes_static_chains_both_ways() {
        let mut tf = TfTree::default();
        let base_from_mount = Rigid::new(DQuat::from_rotation_z(0.3), DVec3::new(1.0, 0.0, 1.5));
        let mount_from_cam = Rigid::new(
            DQuat::from_xyzw(-0.5, 0.5, -0.5, 0.5),
            DVec3::new(0.1, 0.0, 0.0),
        );
        let base_from_lidar = Rigid::from_translation(DVec3::new(0.0, 0.0, 2.0));
        tf.add_static(&edge("/base_link", "mount", base_from_mount));
        tf.add_static(&edge("mount", "cam", mount_from_cam));
        tf.add_static(&edge("base_link", "lidar", base_from_lidar));
        let got = tf.static_transform("base_link", "cam").unwrap();
        let (r, t) = got.difference(base_from_mount * mount_from_cam);
        assert!(r < 1e-12 && t < 1e-12);
        let lidar_from_cam = tf.static_transform("lidar", "cam").unwrap();
        let (r, t) =
            lidar_from_cam.difference(base_from_lidar.inverse() * base_from_mount * mount_from_cam);
        assert!(r < 1e-12 && t < 1e-12);
        assert!(tf.static_transform("base_link", "elsewhere").is_none());
    }

    #[test]
    fn a_stationary_vehicle_still_has_a_trajectory() {
        let mut tf = TfTree::default();
        for i in 0..5 {
            let mut m = edge("odom", "base_link", Rigid::from_translation(DVec3::X));
            m.stamp_nanos = i * 10;
            tf.add_dynamic(&m);
        }
        // A mount published on /tf is a constant edge from a non-fixed frame: static.
        let mut m = edge("base_link", "lidar", Rigid::from_translation(DVec3::Z));
        tf.add_dynamic(&m);
        m.stamp_nanos = 40;
        tf.add_dynamic(&m);
        tf.promote_constant_dynamic_edges();
        assert_eq!(
            tf.default_trajectory_frames(),
            Some(("odom".into(), "base_link".into()))
        );
        assert_eq!(tf.trajectory("odom", "base_link").unwrap().len(), 5);
        assert!(tf.static_transform("base_link", "lidar").is_some());
    }

    #[test]
    fn trajectory_through_two_dynamic_edges() {
        let mut tf = TfTree::default();
        for i in 0..10 {
            let s = i as i64 * 100;
            let mut m = edge(
                "odom",
                "base_link",
                Rigid::from_translation(DVec3::new(i as f64, 0.0, 0.0)),
            );
            m.stamp_nanos = s;
            tf.add_dynamic(&m);
        }
        let mut m = edge(
            "map",
            "odom",
            Rigid::from_translation(DVec3::new(0.0, 5.0, 0.0)),
        );
        tf.add_dynamic(&m);
        m.stamp_nanos = 900;
        tf.add_dynamic(&m);
        assert_eq!(
            tf.default_trajectory_frames(),
            Some(("odom".into(), "base_link".into()))
        );
        let traj = tf.trajectory("map", "base_link").unwrap();
        assert_eq!(traj.len(), 10);
        let p = traj.world_from_vehicle(450).unwrap();
        assert!((p.translation - DVec3::new(4.5, 5.0, 0.0)).length() < 1e-12);
    }
}
