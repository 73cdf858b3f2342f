//! Pose-graph unification of pairwise calibrations (supplementary A2.1's "pairwise + pose
//! graph" baseline): every sensor is a node `vehicle_from_sensor`, every pairwise result an edge
//! `parent_from_child` with a 6 × 6 information matrix, and one Levenberg–Marquardt solve makes
//! the rig consistent.
//!
//! How it works. Tangents are "SO(3) × R³ on the right", the convention of
//! [`Rigid::perturbed_right`]: `T ⊞ (ω, v) = T · (exp ω, v)`, rotation first. An edge
//! `(a, b, Z, Λ)` measures `Z = a_from_b` with information `Λ` in the tangent of `Z`; its
//! residual at poses `T_a`, `T_b` (both `vehicle_from_·`) is the tangent of
//! `Δ = Z⁻¹ · T_a⁻¹ · T_b` (zero when the rig agrees with the measurement) and its cost is
//! `ρ(eᵀ Λ e)` with a Huber kernel on the whitened norm (k = 3: a pairwise result that failed
//! is down-weighted, not trusted). Every node also has a weak prior on its initial guess
//! ([`PRIOR_SIGMA_DEG`], [`PRIOR_SIGMA_M`]) so a sensor no edge reaches stays where it was and the system is never singular.
//! One sensor is fixed (the gauge: the vehicle frame is where the reference sensor says it is).
//! Jacobians are central differences of the residuals (the graph has tens of nodes, not
//! thousands), the normal equations are dense and solved by Cholesky, and the damping follows
//! the usual accept / reject rule.
//!
//! Information from another parametrisation (ICP's left perturbation in the vehicle frame,
//! the checkerboard solve's right perturbation of `camera_from_vehicle`) is carried over by
//! [`reparametrise`]: with `G = ∂ξ_source / ∂ξ_edge` at the solution, `Λ_edge = Gᵀ Λ_source G`.

use glam::DVec3;

use crate::calib::Rig;
use crate::geometry::{Rigid, so3};

/// Standard deviations of every node's prior on its initial guess: only there to keep sensors
/// that no edge reaches in place and the system regular, so loose enough not to pull a sensor
/// measured to a few centimetres.
pub const PRIOR_SIGMA_DEG: f64 = 20.0;
pub const PRIOR_SIGMA_M: f64 = 5.0;

/// One pairwise result: `parent_from_child` measured by `source` (e.g. "icp", "mi").
#[derive(Clone, Debug)]
pub struct Edge {
    pub parent: String,
    pub child: String,
    pub parent_from_child: Rigid,
    /// Row-major 6 × 6 in the right tangent of `parent_from_child` (rotation, translation).
    pub information: [f64; 36],
    pub source: String,
}

/// How well the solved rig agrees with one edge.
#[derive(Clone, Debug)]
pub struct EdgeAgreement {
    pub parent: String,
    pub child: String,
    pub source: String,
    pub rotation_deg: f64,
    pub translation_m: f64,
    /// `√(eᵀ Λ e)`: the disagreement in the edge's own standard deviations.
    pub whitened: f64,
}

/// The tangent `(ω, v)` of `t` (inverse of `Rigid::IDENTITY.perturbed_right`).
pub fn tangent(t: Rigid) -> [f64; 6] {
    let w = so3::log(t.rotation);
    [
        w.x,
        w.y,
        w.z,
        t.translation.x,
        t.translation.y,
        t.translation.z,
    ]
}

fn moved(t: Rigid, x: &[f64]) -> Rigid {
    t.perturbed_right(DVec3::new(x[0], x[1], x[2]), DVec3::new(x[3], x[4], x[5]))
}

/// Diagonal information of standard deviations `rotation_rad` (each axis) and `translation_m`.
pub fn diagonal(rotation_rad: f64, translation_m: f64) -> [f64; 36] {
    let mut m = [0.0; 36];
    for i in 0..3 {
        m[i * 6 + i] = 1.0 / (rotation_rad * rotation_rad);
        m[(i + 3) * 6 + i + 3] = 1.0 / (translation_m * translation_m);
    }
    m
}

/// Information `source` of another tangent carried into the edge tangent: `to_source` maps an
/// edge tangent to the source tangent (and 0 to 0); `Λ = Gᵀ Λ_source G`, `G` its Jacobian.
pub fn reparametrise(source: &[f64; 36], to_source: impl Fn(&[f64; 6]) -> [f64; 6]) -> [f64; 36] {
    let h = 1e-6;
    let mut g = [[0.0; 6]; 6]; // g[row = source][col = edge]
    for col in 0..6 {
        let mut x = [0.0; 6];
        x[col] = h;
        let up = to_source(&x);
        x[col] = -h;
        let down = to_source(&x);
        for row in 0..6 {
            g[row][col] = (up[row] - down[row]) / (2.0 * h);
        }
    }
    let mut out = [0.0; 36];
    for i in 0..6 {
        for j in 0..6 {
            let mut s = 0.0;
            for a in 0..6 {
                for b in 0..6 {
                    s += g[a][i] * source[a * 6 + b] * g[b][j];
                }
            }
            out[i * 6 + j] = s;
        }
    }
    out
}

/// Whitened cost `eᵀ Λ e`.
fn quadratic(e: &[f64; 6], info: &[f64; 36]) -> f64 {
    let mut s = 0.0;
    for i in 0..6 {
        for j in 0..6 {
            s += e[i] * info[i * 6 + j] * e[j];
        }
    }
    s
}

/// Huber weight of a whitened norm (k = 3).
fn huber_weight(whitened: f64) -> f64 {
    const K: f64 = 3.0;
    if whitened <= K { 1.0 } else { K / whitened }
}

/// Robust cost of a whitened squared norm `q`.
fn huber_cost(q: f64) -> f64 {
    const K: f64 = 3.0;
    let s = q.sqrt();
    if s <= K { q } else { 2.0 * K * s - K * K }
}

/// A factor: a measured edge between two nodes, or a prior on one (`parent` = `None`).
#[derive(Clone, Debug)]
struct Factor {
    parent: Option<usize>,
    child: usize,
    parent_from_child: Rigid,
    information: [f64; 36],
    edge: Option<usize>,
}

/// The graph over a rig's sensors.
#[derive(Clone, Debug)]
pub struct PoseGraph {
    names: Vec<String>,
    poses: Vec<Rigid>,
    fixed: usize,
    factors: Vec<Factor>,
    edges: Vec<Edge>,
    lambda: f64,
    pub iterations: usize,
    pub converged: bool,
}

/// A pose graph that cannot be built or an edge it refuses.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum PoseGraphError {
    #[error("no sensor '{0}' in the pose graph")]
    UnknownSensor(String),
    #[error("no sensor '{0}' to fix the pose graph's gauge")]
    UnknownGauge(String),
    #[error("edge from '{0}' to itself")]
    SelfEdge(String),
    #[error("edge {parent} → {child} ({source_name}): information is not finite and non-negative")]
    BadInformation {
        parent: String,
        child: String,
        source_name: String,
    },
}

impl PoseGraph {
    /// Nodes are `rig`'s sensors at their current extrinsics (each with a weak prior there);
    /// `fixed` is the gauge.
    pub fn new(rig: &Rig, fixed: &str) -> Result<Self, PoseGraphError> {
        let names: Vec<String> = rig.sensors.iter().map(|s| s.name.clone()).collect();
        let fixed = names
            .iter()
            .position(|n| n == fixed)
            .ok_or_else(|| PoseGraphError::UnknownGauge(fixed.to_owned()))?;
        let poses: Vec<Rigid> = rig.sensors.iter().map(|s| s.vehicle_from_sensor).collect();
        let prior = diagonal(PRIOR_SIGMA_DEG.to_radians(), PRIOR_SIGMA_M);
        let factors = poses
            .iter()
            .enumerate()
            .map(|(i, &p)| Factor {
                parent: None,
                child: i,
                parent_from_child: p,
                information: prior,
                edge: None,
            })
            .collect();
        Ok(Self {
            names,
            poses,
            fixed,
            factors,
            edges: Vec::new(),
            lambda: 1e-4,
            iterations: 0,
            converged: false,
        })
    }

    fn index(&self, name: &str) -> Result<usize, PoseGraphError> {
        self.names
            .iter()
            .position(|n| n == name)
            .ok_or_else(|| PoseGraphError::UnknownSensor(name.to_owned()))
    }

    /// Add a pairwise result; its information must be symmetric positive semi-definite and finite.
    pub fn add_edge(&mut self, edge: Edge) -> Result<(), PoseGraphError> {
        let parent = self.index(&edge.parent)?;
        let child = self.index(&edge.child)?;
        if parent == child {
            return Err(PoseGraphError::SelfEdge(edge.parent));
        }
        if edge.information.iter().any(|v| !v.is_finite())
            || (0..6).any(|i| edge.information[i * 6 + i] < 0.0)
        {
            return Err(PoseGraphError::BadInformation {
                parent: edge.parent,
                child: edge.child,
                source_name: edge.source,
            });
        }
        self.factors.push(Factor {
            parent: Some(parent),
            child,
            parent_from_child: edge.parent_from_child,
            information: edge.information,
            edge: Some(self.edges.len()),
        });
        self.edges.push(edge);
        self.converged = false;
        Ok(())
    }

    pub fn edges(&self) -> &[Edge] {
        &self.edges
    }

    fn residual(f: &Factor, poses: &[Rigid]) -> [f64; 6] {
        let vehicle_from_parent = f.parent.map_or(Rigid::IDENTITY, |p| poses[p]);
        // Δ = Z⁻¹ · T_a⁻¹ · T_b
        tangent(f.parent_from_child.inverse() * vehicle_from_parent.inverse() * poses[f.child])
    }

    /// Robust total cost.
    pub fn cost(&self) -> f64 {
        self.cost_at(&self.poses)
    }

    fn cost_at(&self, poses: &[Rigid]) -> f64 {
        self.factors
            .iter()
            .map(|f| huber_cost(quadratic(&Self::residual(f, poses), &f.information)))
            .sum()
    }

    /// Free nodes' positions in the state vector.
    fn slot(&self, node: usize) -> Option<usize> {
        match node.cmp(&self.fixed) {
            std::cmp::Ordering::Less => Some(node),
            std::cmp::Ordering::Equal => None,
            std::cmp::Ordering::Greater => Some(node - 1),
        }
    }

    /// One Levenberg–Marquardt iteration; returns the cost after it.
    pub fn step(&mut self) -> f64 {
        let free = self.poses.len() - 1;
        let n = 6 * free;
        let before = self.cost();
        if self.converged || n == 0 {
            self.converged = true;
            return before;
        }
        self.iterations += 1;
        let mut h = vec![0.0; n * n];
        let mut g = vec![0.0; n];
        let eps = 1e-6;
        for f in &self.factors {
            let e = Self::residual(f, &self.poses);
            let w = huber_weight(quadratic(&e, &f.information).sqrt());
            // Jacobian columns for each free node of the factor: (slot, 6 columns of 6).
            let mut blocks: Vec<(usize, [[f64; 6]; 6])> = Vec::new();
            for node in f.parent.into_iter().chain([f.child]) {
                let Some(slot) = self.slot(node) else {
                    continue;
                };
                let mut cols = [[0.0; 6]; 6];
                let mut poses = self.poses.clone();
                for (k, col) in cols.iter_mut().enumerate() {
                    let mut d = [0.0; 6];
                    d[k] = eps;
                    poses[node] = moved(self.poses[node], &d);
                    let up = Self::residual(f, &poses);
                    d[k] = -eps;
                    poses[node] = moved(self.poses[node], &d);
                    let down = Self::residual(f, &poses);
                    for r in 0..6 {
                        col[r] = (up[r] - down[r]) / (2.0 * eps);
                    }
                }
                blocks.push((slot, cols));
            }
            // Λ e and Λ J columns.
            let info = &f.information;
            let li = |v: &[f64; 6]| {
                let mut o = [0.0; 6];
                for i in 0..6 {
                    o[i] = (0..6).map(|j| info[i * 6 + j] * v[j]).sum();
                }
                o
            };
            let le = li(&e);
            for (sa, ca) in &blocks {
                for (ka, col_a) in ca.iter().enumerate() {
                    let row = sa * 6 + ka;
                    g[row] += w * col_a.iter().zip(&le).map(|(a, b)| a * b).sum::<f64>();
                    let lca = li(col_a);
                    for (sb, cb) in &blocks {
                        for (kb, col_b) in cb.iter().enumerate() {
                            let c = sb * 6 + kb;
                            h[row * n + c] +=
                                w * col_b.iter().zip(&lca).map(|(a, b)| a * b).sum::<f64>();
                        }
                    }
                }
            }
        }
        for _ in 0..12 {
            let mut damped = h.clone();
            for i in 0..n {
                damped[i * n + i] += self.lambda * h[i * n + i].max(1e-9);
            }
            let rhs: Vec<f64> = g.iter().map(|v| -v).collect();
            let Some(dx) = crate::geometry::spd::solve(&damped, &rhs) else {
                self.lambda *= 10.0;
                continue;
            };
            let mut poses = self.poses.clone();
            for (node, pose) in poses.iter_mut().enumerate() {
                if let Some(slot) = self.slot(node) {
                    *pose = moved(*pose, &dx[slot * 6..slot * 6 + 6]);
                }
            }
            let after = self.cost_at(&poses);
            if after <= before {
                self.poses = poses;
                self.lambda = (self.lambda * 0.3).max(1e-9);
                let largest = dx.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                if largest < 1e-9 || before - after <= 1e-12 * before.max(1e-300) {
                    self.converged = true;
                }
                return after;
            }
            self.lambda *= 10.0;
        }
        self.converged = true;
        before
    }

    /// Iterate to convergence (at most `iterations`).
    pub fn solve(&mut self, iterations: usize) -> f64 {
        let mut cost = self.cost();
        while !self.converged && self.iterations < iterations {
            cost = self.step();
        }
        cost
    }

    /// `rig` with every node's solved extrinsic.
    pub fn apply(&self, rig: &Rig) -> Rig {
        let mut out = rig.clone();
        for (name, pose) in self.names.iter().zip(&self.poses) {
            if let Some(s) = out.sensor_mut(name) {
                s.vehicle_from_sensor = *pose;
            }
        }
        out
    }

    /// How far the current poses are from each edge.
    pub fn agreement(&self) -> Vec<EdgeAgreement> {
        self.factors
            .iter()
            .filter_map(|f| {
                let edge = &self.edges[f.edge?];
                let e = Self::residual(f, &self.poses);
                Some(EdgeAgreement {
                    parent: edge.parent.clone(),
                    child: edge.child.clone(),
                    source: edge.source.clone(),
                    rotation_deg: DVec3::new(e[0], e[1], e[2]).length().to_degrees(),
                    translation_m: DVec3::new(e[3], e[4], e[5]).length(),
                    whitened: quadratic(&e, &f.information).max(0.0).sqrt(),
                })
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calib::{Sensor, SensorKind};
    use glam::DQuat;

    fn pose(rx: f64, ry: f64, rz: f64, t: [f64; 3]) -> Rigid {
        Rigid::new(
            DQuat::from_euler(glam::EulerRot::ZYX, rz, ry, rx),
            DVec3::from_array(t),
        )
    }

    fn rig(poses: &[(&str, Rigid)]) -> Rig {
        Rig {
            vehicle_frame: "base_link".into(),
            sensors: poses
                .iter()
                .map(|(n, p)| Sensor {
                    name: n.to_string(),
                    kind: SensorKind::Lidar,
                    frame_id: n.to_string(),
                    topics: vec![],
                    vehicle_from_sensor: *p,
                    camera: None,
                })
                .collect(),
        }
    }

    fn truth() -> Rig {
        rig(&[
            ("top", pose(0.01, -0.02, 1.5, [1.0, 0.0, 1.8])),
            ("front", pose(0.0, 0.05, 0.02, [2.2, 0.1, 1.2])),
            ("cam_a", pose(-1.6, 0.01, -1.55, [2.0, 0.5, 1.5])),
            ("cam_b", pose(-1.5, -0.03, 1.6, [-0.5, -0.6, 1.6])),
        ])
    }

    fn measured(truth: &Rig, a: &str, b: &str, noise: Rigid, info: [f64; 36], src: &str) -> Edge {
        let ta = truth.sensor(a).unwrap().vehicle_from_sensor;
        let tb = truth.sensor(b).unwrap().vehicle_from_sensor;
        Edge {
            parent: a.into(),
            child: b.into(),
            parent_from_child: ta.inverse() * tb * noise,
            information: info,
            source: src.into(),
        }
    }

    fn perturbed(truth: &Rig, seed: u64) -> Rig {
        let mut r = truth.clone();
        for (i, s) in r.sensors.iter_mut().enumerate().skip(1) {
            let k = (seed as f64 + 1.0) * (i as f64 + 1.0);
            s.vehicle_from_sensor = s.vehicle_from_sensor.perturbed_right(
                DVec3::new(k.sin(), k.cos(), (2.0 * k).sin()) * 2f64.to_radians(),
                DVec3::new((3.0 * k).cos(), (5.0 * k).sin(), k.cos()) * 0.2,
            );
        }
        r
    }

    #[test]
    fn exact_edges_give_the_truth_from_several_starts() {
        let truth = truth();
        let info = diagonal(0.1f64.to_radians(), 0.01);
        for seed in 0..3 {
            let mut g = PoseGraph::new(&perturbed(&truth, seed), "top").unwrap();
            for (a, b) in [
                ("top", "front"),
                ("top", "cam_a"),
                ("front", "cam_a"),
                ("top", "cam_b"),
            ] {
                g.add_edge(measured(&truth, a, b, Rigid::IDENTITY, info, "exact"))
                    .unwrap();
            }
            g.solve(50);
            let solved = g.apply(&truth);
            for s in &truth.sensors {
                let (r, t) = solved
                    .sensor(&s.name)
                    .unwrap()
                    .vehicle_from_sensor
                    .difference(s.vehicle_from_sensor);
                // The weak priors pull by (edge σ / prior σ)² ≪ 1e-4 of the start error.
                assert!(
                    r.to_degrees() < 2e-3 && t < 2e-4,
                    "seed {seed} {}: {r} {t}",
                    s.name
                );
            }
            assert!(g.agreement().iter().all(|a| a.whitened < 0.1));
        }
    }

    #[test]
    fn inconsistent_loops_split_by_information_and_outliers_are_down_weighted() {
        let truth = truth();
        let sharp = diagonal(0.05f64.to_radians(), 0.005);
        let loose = diagonal(0.5f64.to_radians(), 0.05);
        let mut g = PoseGraph::new(&truth, "top").unwrap();
        g.add_edge(measured(
            &truth,
            "top",
            "front",
            Rigid::IDENTITY,
            sharp,
            "icp",
        ))
        .unwrap();
        // cam_a seen from both LiDARs: the sharp edge is right, the loose one 3 cm off.
        g.add_edge(measured(
            &truth,
            "top",
            "cam_a",
            Rigid::IDENTITY,
            sharp,
            "a",
        ))
        .unwrap();
        let off = Rigid::from_translation(DVec3::new(0.03, 0.0, 0.0));
        g.add_edge(measured(&truth, "front", "cam_a", off, loose, "b"))
            .unwrap();
        // cam_b: one good edge and one 20 cm outlier of the same information.
        g.add_edge(measured(
            &truth,
            "top",
            "cam_b",
            Rigid::IDENTITY,
            sharp,
            "c",
        ))
        .unwrap();
        let outlier = Rigid::from_translation(DVec3::new(0.0, 0.2, 0.0));
        g.add_edge(measured(&truth, "front", "cam_b", outlier, sharp, "d"))
            .unwrap();
        g.solve(100);
        let solved = g.apply(&truth);
        let err = |n: &str| {
            solved
                .sensor(n)
                .unwrap()
                .vehicle_from_sensor
                .difference(truth.sensor(n).unwrap().vehicle_from_sensor)
        };
        // 100:1 information: the compromise sits ~1/101 of the way to the loose edge.
        let (_, ta) = err("cam_a");
        assert!(ta < 0.003 && ta > 0.0001, "cam_a {ta}");
        // Squared loss would split the outlier in half (10 cm); Huber keeps well under that.
        let (_, tb) = err("cam_b");
        assert!(tb < 0.05, "cam_b {tb}");
        let worst = g
            .agreement()
            .into_iter()
            .max_by(|a, b| a.whitened.total_cmp(&b.whitened))
            .unwrap();
        assert_eq!(worst.source, "d");
    }

    #[test]
    fn reparametrised_information_keeps_the_cost() {
        // ICP's tangent: left perturbation in the vehicle frame of vehicle_from_child, with the
        // parent fixed. The same small motion costs the same in both tangents.
        let parent = pose(0.1, 0.2, 0.3, [1.0, 2.0, 0.5]);
        let child = pose(-0.4, 0.1, 1.2, [2.0, -1.0, 1.5]);
        let z = parent.inverse() * child;
        let mut source = diagonal(0.01, 0.02);
        source[1] = 30.0;
        source[6] = 30.0;
        let to_source = |x: &[f64; 6]| {
            let moved_child = parent * moved(z, x);
            tangent(moved_child * child.inverse())
        };
        let info = reparametrise(&source, to_source);
        let x = [1e-4, -2e-4, 5e-5, 1e-3, 2e-3, -1e-3];
        let s = to_source(&x);
        let (a, b) = (quadratic(&x, &info), quadratic(&s, &source));
        assert!((a - b).abs() < 1e-3 * b, "{a} vs {b}");
    }

    #[test]
    fn bad_edges_are_refused_by_name() {
        let mut g = PoseGraph::new(&truth(), "top").unwrap();
        let mut e = measured(
            &truth(),
            "top",
            "front",
            Rigid::IDENTITY,
            diagonal(0.1, 0.1),
            "x",
        );
        e.information[0] = f64::NAN;
        assert!(
            g.add_edge(e)
                .unwrap_err()
                .to_string()
                .contains("top → front")
        );
        let e = measured(
            &truth(),
            "top",
            "top",
            Rigid::IDENTITY,
            diagonal(0.1, 0.1),
            "x",
        );
        assert!(g.add_edge(e).is_err());
        assert!(PoseGraph::new(&truth(), "nowhere").is_err());
    }
}
