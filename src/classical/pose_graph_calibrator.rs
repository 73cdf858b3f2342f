//! Pairwise calibration unified by a pose graph, as a [`Calibrator`] (the paper's pose-graph
//! baseline): `rigcal calibrate --method pose-graph` and the studio's optimiser panel.
//!
//! How it works. Preparation builds every pairwise problem of the rig: point-to-plane ICP for
//! every LiDAR pair (each LiDAR against every earlier one, [`super::icp_calibrator`]), and
//! every camera against every LiDAR, by checkerboard edges and planes where the pair sees
//! boards ([`super::target_calibrator`]) and, for a camera that sees boards with no LiDAR, by
//! mutual information ([`super::mi_calibrator`]) with every LiDAR that puts at least
//! [`MIN_MI_POINTS`] points into its view; pairs that cannot be set up (no overlap, no boards,
//! no reflectivity) and mutual-information searches that never leave their start are skipped
//! and named in [`PoseGraphCalibrator::skipped`]. Steps run the
//! pairwise problems one after the other; each finished one becomes edges `parent_from_child`
//! with information matrices (ICP: `JᵀJ/σ²` of its points, [`super::icp::IcpProblem::information`];
//! checkerboards: the solve's `JᵀJ/σ²`; mutual information, which has no curvature worth
//! trusting: a nominal 0.25° / 5 cm). Then the [`PoseGraph`] is solved with the reference LiDAR
//! fixed, and its rig is the result. Losses report each stage's own terms, then the graph's
//! cost and every edge's disagreement with the solved rig.

use crate::error::RunError;
use rayon::prelude::*;

use super::icp::IcpConfig;
use super::icp_calibrator::IcpCalibrator;
use super::mi_calibrator::MiCalibrator;
use super::mutual_info::MiConfig;
use super::pose_graph::{Edge, EdgeAgreement, PoseGraph, diagonal, reparametrise, tangent};
use super::target::{BoardCache, TargetConfig};
use super::target_calibrator::TargetCalibrator;
use crate::calib::Rig;
use crate::geometry::Rigid;
use crate::log::Drive;
use crate::optim::runner::{Calibrator, StepReport};

/// How camera–LiDAR pairs are measured.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum CameraPairs {
    /// Checkerboards where the pair sees boards, mutual information otherwise.
    #[default]
    Auto,
    Target,
    MutualInformation,
}

#[derive(Clone, Debug)]
pub struct PoseGraphConfig {
    pub camera_pairs: CameraPairs,
    /// Sweeps per LiDAR for ICP and frames per camera for mutual information.
    pub frames: usize,
    /// Levenberg–Marquardt iterations of the graph.
    pub graph_iterations: usize,
    /// Nominal standard deviations of a mutual-information edge.
    pub mi_sigma_deg: f64,
    pub mi_sigma_m: f64,
}

impl Default for PoseGraphConfig {
    fn default() -> Self {
        Self {
            camera_pairs: CameraPairs::Auto,
            frames: 3,
            graph_iterations: 50,
            mi_sigma_deg: 0.25,
            mi_sigma_m: 0.05,
        }
    }
}

/// Fewest LiDAR points in a camera's view for a mutual-information edge.
pub const MIN_MI_POINTS: usize = 2000;

enum Pairwise {
    Icp {
        reference: String,
        run: IcpCalibrator,
    },
    Mi {
        lidar: String,
        run: MiCalibrator,
    },
    Target {
        lidar: String,
        run: TargetCalibrator,
    },
}

impl Pairwise {
    fn calibrator(&mut self) -> &mut dyn Calibrator {
        match self {
            Pairwise::Icp { run, .. } => run,
            Pairwise::Mi { run, .. } => run,
            Pairwise::Target { run, .. } => run,
        }
    }

    fn label(&self) -> String {
        match self {
            Pairwise::Icp { reference, .. } => format!("icp vs {reference}"),
            Pairwise::Mi { lidar, .. } => format!("mi vs {lidar}"),
            Pairwise::Target { lidar, .. } => format!("target vs {lidar}"),
        }
    }
}

pub struct PoseGraphCalibrator {
    initial: Rig,
    pairwise: Vec<Pairwise>,
    stage: usize,
    stage_steps: usize,
    graph: PoseGraph,
    config: PoseGraphConfig,
    skipped: Vec<String>,
    max_steps: usize,
    live: Rig,
}

impl PoseGraphCalibrator {
    /// Prepare every pairwise problem of `rig` on the drive (within `segments_nanos`), with
    /// `reference` (a LiDAR) as the graph's fixed node.
    pub fn from_drive(
        drive: &Drive,
        rig: &Rig,
        reference: &str,
        segments_nanos: &[(i64, i64)],
        config: PoseGraphConfig,
    ) -> Result<Self, RunError> {
        if !rig.lidars().any(|l| l.name == reference) {
            return Err(RunError::no_sensor("LiDAR", reference));
        }
        // The reference first, so ICP edges hang off it where they can.
        let mut lidars: Vec<String> = vec![reference.to_string()];
        lidars.extend(
            rig.lidars()
                .map(|l| l.name.clone())
                .filter(|l| l != reference),
        );
        let cameras: Vec<String> = rig
            .cameras()
            .filter(|c| c.camera.is_some())
            .map(|c| c.name.clone())
            .collect();
        let mut pairwise = Vec::new();
        let mut skipped = Vec::new();
        for (i, l) in lidars.iter().enumerate() {
            if i + 1 >= lidars.len() {
                break;
            }
            // ICP registers every LiDAR of the rig it is given against the reference: give it
            // the later ones only, so each pair is measured once.
            let mut sub = rig.clone();
            sub.sensors
                .retain(|s| s.camera.is_some() || lidars[i..].contains(&s.name));
            match IcpCalibrator::from_drive(
                drive,
                &sub,
                l,
                config.frames,
                segments_nanos,
                IcpConfig::default(),
            ) {
                Ok(run) => pairwise.push(Pairwise::Icp {
                    reference: l.clone(),
                    run,
                }),
                Err(e) => skipped.push(format!("icp against {l}: {e}")),
            }
        }
        // Cameras: checkerboards first (Auto, Target); a camera that no LiDAR sees boards with
        // falls back to mutual information (Auto, MutualInformation).
        let mut by_boards: Vec<String> = Vec::new();
        if config.camera_pairs != CameraPairs::MutualInformation {
            // Each camera's images are searched for boards once (the cache), the cameras of
            // one LiDAR in parallel.
            let boards = BoardCache::default();
            for l in &lidars {
                let made: Vec<_> = cameras
                    .par_iter()
                    .map(|cam| {
                        TargetCalibrator::from_drive(
                            drive,
                            rig,
                            l,
                            std::slice::from_ref(cam),
                            segments_nanos,
                            TargetConfig::default(),
                            &boards,
                        )
                    })
                    .collect();
                for (cam, made) in cameras.iter().zip(made) {
                    match made {
                        Ok(run) => {
                            by_boards.push(cam.clone());
                            pairwise.push(Pairwise::Target {
                                lidar: l.clone(),
                                run,
                            });
                        }
                        Err(e) => skipped.push(format!("checkerboards {e}")),
                    }
                }
            }
        }
        if config.camera_pairs != CameraPairs::Target {
            for l in &lidars {
                for cam in cameras.iter().filter(|c| !by_boards.contains(c)) {
                    let made = MiCalibrator::from_drive(
                        drive,
                        rig,
                        l,
                        std::slice::from_ref(cam),
                        config.frames,
                        segments_nanos,
                        MiConfig::default(),
                    );
                    match made {
                        Ok(run) => {
                            let points: usize =
                                run.problems().iter().map(|(p, _)| p.point_count()).sum();
                            if points >= MIN_MI_POINTS {
                                pairwise.push(Pairwise::Mi {
                                    lidar: l.clone(),
                                    run,
                                });
                            } else {
                                skipped.push(format!(
                                    "mutual information {cam} × {l}: the camera sees {points} of the LiDAR's points (needs {MIN_MI_POINTS})"
                                ));
                            }
                        }
                        Err(e) => skipped.push(format!("mutual information {cam} × {l}: {e}")),
                    }
                }
            }
        }
        if pairwise.is_empty() {
            return Err(RunError::NotEnoughData(format!(
                "no pairwise calibration could be set up: {}",
                skipped.join("; ")
            )));
        }
        let max_steps = pairwise
            .iter_mut()
            .map(|p| p.calibrator().max_steps())
            .sum::<usize>()
            + config.graph_iterations;
        Ok(Self {
            initial: rig.clone(),
            pairwise,
            stage: 0,
            stage_steps: 0,
            graph: PoseGraph::new(rig, reference)?,
            config,
            skipped,
            max_steps,
            live: rig.clone(),
        })
    }

    /// Pairs that could not be set up, with the reason.
    pub fn skipped(&self) -> &[String] {
        &self.skipped
    }

    /// The graph (its iterations, cost and convergence).
    pub fn graph(&self) -> &PoseGraph {
        &self.graph
    }

    /// The graph's edges so far.
    pub fn edges(&self) -> &[Edge] {
        self.graph.edges()
    }

    /// Every edge's disagreement with the current graph solution.
    pub fn agreement(&self) -> Vec<EdgeAgreement> {
        self.graph.agreement()
    }

    fn vehicle_from(&self, name: &str) -> Rigid {
        self.initial
            .sensor(name)
            .map_or(Rigid::IDENTITY, |s| s.vehicle_from_sensor)
    }

    /// The finished pairwise problem's results as edges, and what it measured nothing for.
    fn harvest(&self, index: usize) -> (Vec<Edge>, Vec<String>) {
        let mut edges = Vec::new();
        let mut notes = Vec::new();
        match &self.pairwise[index] {
            Pairwise::Icp { reference, run } => {
                let vehicle_from_parent = self.vehicle_from(reference);
                for (child, problem) in run.problems() {
                    let x = problem.vehicle_from_source;
                    let z = vehicle_from_parent.inverse() * x;
                    // ICP's tangent: X ← (exp ω, τ) · X in the vehicle frame.
                    let information = reparametrise(&problem.information(), |e| {
                        let moved = vehicle_from_parent * z.perturbed_right(v3(e, 0), v3(e, 3));
                        tangent(moved * x.inverse())
                    });
                    edges.push(Edge {
                        parent: reference.clone(),
                        child: child.clone(),
                        parent_from_child: z,
                        information,
                        source: "icp".into(),
                    });
                }
            }
            Pairwise::Mi { lidar, run } => {
                let vehicle_from_parent = self.vehicle_from(lidar);
                for (problem, search) in run.problems() {
                    // A search that never left its start measured nothing: the start is the
                    // guess the graph already has, and an edge would only pull towards it.
                    if search.best == search.start {
                        notes.push(format!(
                            "mutual information {} × {lidar}: no pose better than the start",
                            problem.camera
                        ));
                        continue;
                    }
                    edges.push(Edge {
                        parent: lidar.clone(),
                        child: problem.camera.clone(),
                        parent_from_child: vehicle_from_parent.inverse() * search.best,
                        information: diagonal(
                            self.config.mi_sigma_deg.to_radians(),
                            self.config.mi_sigma_m,
                        ),
                        source: "mi".into(),
                    });
                }
            }
            Pairwise::Target { lidar, run } => {
                let vehicle_from_parent = self.vehicle_from(lidar);
                for (camera, _, solution) in run.solutions() {
                    let c = solution.vehicle_from_camera.inverse();
                    let z = vehicle_from_parent.inverse() * solution.vehicle_from_camera;
                    let rms_sq = (solution.plane_rms_m.powi(2) + solution.border_rms_m.powi(2))
                        .max(0.01 * 0.01);
                    let scaled = solution.information.map(|v| v / rms_sq);
                    // The solve's tangent: camera_from_vehicle · (exp ω, v).
                    let information = reparametrise(&scaled, |e| {
                        let moved = vehicle_from_parent * z.perturbed_right(v3(e, 0), v3(e, 3));
                        tangent(c.inverse() * moved.inverse())
                    });
                    edges.push(Edge {
                        parent: lidar.clone(),
                        child: camera,
                        parent_from_child: z,
                        information,
                        source: "target".into(),
                    });
                }
            }
        }
        (edges, notes)
    }

    fn graph_losses(&self) -> Vec<(String, f64)> {
        let mut out = vec![("pose graph cost".to_string(), self.graph.cost())];
        for a in self.graph.agreement() {
            out.push((
                format!("edge σ/{} {}→{}", a.source, a.parent, a.child),
                a.whitened,
            ));
        }
        out
    }
}

fn v3(e: &[f64; 6], at: usize) -> glam::DVec3 {
    glam::DVec3::new(e[at], e[at + 1], e[at + 2])
}

impl Calibrator for PoseGraphCalibrator {
    fn name(&self) -> &str {
        "pairwise + pose graph"
    }

    fn max_steps(&self) -> usize {
        self.max_steps
    }

    fn step(&mut self) -> StepReport {
        if self.stage < self.pairwise.len() {
            let index = self.stage;
            let label = self.pairwise[index].label();
            let c = self.pairwise[index].calibrator();
            let report = c.step();
            let limit = c.max_steps();
            self.live = {
                let moved = c.current();
                let mut live = self.live.clone();
                // Show only what this stage moves (its non-reference sensors).
                for s in &moved.sensors {
                    let before = self.initial.sensor(&s.name).map(|i| i.vehicle_from_sensor);
                    if before != Some(s.vehicle_from_sensor)
                        && let Some(l) = live.sensor_mut(&s.name)
                    {
                        l.vehicle_from_sensor = s.vehicle_from_sensor;
                    }
                }
                live
            };
            self.stage_steps += 1;
            if report.done || self.stage_steps >= limit {
                let (edges, notes) = self.harvest(index);
                self.skipped.extend(notes);
                for edge in edges {
                    if let Err(e) = self.graph.add_edge(edge) {
                        self.skipped.push(e.to_string());
                    }
                }
                self.stage += 1;
                self.stage_steps = 0;
            }
            let losses = report
                .losses
                .into_iter()
                .map(|(k, v)| (format!("{label}: {k}"), v))
                .collect();
            return StepReport {
                losses,
                done: false,
            };
        }
        self.graph.step();
        self.live = self.graph.apply(&self.initial);
        StepReport {
            losses: self.graph_losses(),
            done: self.graph.converged || self.graph.iterations >= self.config.graph_iterations,
        }
    }

    fn current(&self) -> Rig {
        self.live.clone()
    }

    fn best(&self) -> Rig {
        if self.stage >= self.pairwise.len() {
            self.graph.apply(&self.initial)
        } else {
            self.live.clone()
        }
    }
}
