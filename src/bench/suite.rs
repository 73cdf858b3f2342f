//! What a bench suite runs: its cases, each a (protocol, row, method, drive, initial
//! perturbation, seed). Identical runs that several tables need (the figure-8 drive at 1° /
//! 10 cm is the trajectory study's figure-8 row, the sensor study's "full" row and the ablation
//! baseline) share one [`Case::key`] and run once.
//!
//! `quick` is the smoke-scale suite (quarter-size images, 2 s drives, short runs: ≤ 10 minutes
//! on two cores); `paper` is the paper's protocol at full length (supplementary A4: six
//! perturbation levels × 10 seeds, five trajectories, the featureless scene, sensor subsets,
//! ablations, PandaSet).

use std::path::PathBuf;

use serde::Serialize;

use crate::sim::trajectories::TrajectoryKind;
use crate::sim::world::SceneKind;
use crate::unical::surface_align::AlignmentLoss;

/// The paper's protocols (method.md §13; supplementary Tables A1, A7, A8, A10).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize)]
pub enum Protocol {
    /// Initial rotation or translation error sweep (Table A7 layout).
    Perturbation,
    /// Drive shapes (Table A8 layout).
    Trajectory,
    /// The featureless scene.
    Featureless,
    /// All sensors, camera-only, LiDAR-only (Table A10 layout).
    Sensors,
    /// UniCal with parts switched off.
    Ablation,
    /// The correspondence term: none, projected ray distance, surface alignment (Table A9).
    Correspondence,
    /// The real PandaSet drive, 1° / 10 cm.
    PandaSet,
}

impl Protocol {
    pub fn title(self) -> &'static str {
        match self {
            Protocol::Perturbation => "Initial perturbation (Table A7 layout)",
            Protocol::Trajectory => "Driving trajectory (Table A8 layout)",
            Protocol::Featureless => "Featureless scene",
            Protocol::Sensors => "Sensor subsets (Table A10 layout)",
            Protocol::Ablation => "Ablations",
            Protocol::Correspondence => "Correspondence loss (Table A9 layout)",
            Protocol::PandaSet => "Real PandaSet drive (pandaset-002), 1° / 10 cm",
        }
    }
}

/// Where a case's drive comes from.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub enum DriveSpec {
    /// A simulated drive (pandaset rig), written once into the bench's `drives/` folder.
    Sim {
        scene: SceneKind,
        trajectory: TrajectoryKind,
        seconds: f64,
        /// Image size factor of the simulator.
        scale: f64,
        seed: u64,
    },
    /// A recorded log with its reference calibration (native file or dataset JSON).
    Log {
        mcap: PathBuf,
        ground_truth: PathBuf,
    },
}

impl DriveSpec {
    /// A short name, also the cache file stem of simulated drives.
    pub fn name(&self) -> String {
        match self {
            DriveSpec::Sim {
                scene,
                trajectory,
                seconds,
                scale,
                seed,
            } => format!(
                "{}-{}-{seconds}s-x{scale}-seed{seed}",
                scene.as_str(),
                trajectory.as_str()
            ),
            DriveSpec::Log { mcap, .. } => mcap
                .file_stem()
                .map_or_else(|| "log".into(), |s| s.to_string_lossy().into_owned()),
        }
    }
}

/// UniCal's settings for a bench run (a subset of [`crate::unical::depth_calib::DepthCalibConfig`]
/// plus how much data it takes).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct UnicalSettings {
    pub iterations: usize,
    pub geometry_init_steps: usize,
    pub geometry_init_rays: usize,
    pub pose_warmup: usize,
    /// Iterations over which the pose rates rise to their value after the warm-up.
    pub pose_ramp: usize,
    pub rays_per_sensor: usize,
    pub rays_per_camera: usize,
    pub sweeps_per_lidar: usize,
    /// Images per camera for the colour term (0: LiDAR-only).
    pub camera_frames: usize,
    /// Image scale the cameras train at.
    pub camera_scale: f64,
    /// LiDAR poses by preconditioned steps (`unical::pose_newton`); false: the paper's Adam.
    pub newton_lidar_poses: bool,
    /// LiDAR depth, intensity, regulariser and geometry initialisation on. Off (camera-only):
    /// no LiDAR ray is rendered and LiDAR extrinsics stay as they are; the LiDAR returns still
    /// place the occupancy grid the camera rays are sampled in.
    pub lidar_supervision: bool,
    /// The correspondence term between cameras.
    pub alignment: AlignmentLoss,
}

/// A calibration method as the bench runs it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub enum Method {
    /// The automatic pipeline, as `rigcal calibrate LOG --out FILE` runs it.
    Pipeline(Box<crate::pipeline::PipelineConfig>),
    UniCal(UnicalSettings),
    /// Target-free edge alignment of every camera against the root LiDAR.
    Edge {
        frames: usize,
        max_steps: usize,
    },
}

impl Method {
    pub fn label(&self) -> &'static str {
        match self {
            Method::Pipeline(_) => "pipeline",
            Method::UniCal(s) if s.camera_frames == 0 => "UniCal (LiDAR only)",
            Method::UniCal(s) if !s.lidar_supervision => "UniCal (camera only)",
            Method::UniCal(_) => "UniCal",
            Method::Edge { .. } => "edge alignment",
        }
    }
}

/// One run of one method.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Case {
    pub protocol: Protocol,
    /// The table row (e.g. "Rotation 2°", "figure8", "LiDAR-only").
    pub row: String,
    pub method: Method,
    pub drive: DriveSpec,
    pub perturb_deg: f64,
    pub perturb_cm: f64,
    pub seed: u64,
}

impl Case {
    /// Cases with equal keys are the same run.
    pub fn key(&self) -> String {
        format!(
            "{}|{}|{}|{}|{:?}",
            self.drive.name(),
            self.perturb_deg,
            self.perturb_cm,
            self.seed,
            self.method
        )
    }
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Suite {
    pub name: String,
    pub cases: Vec<Case>,
}

/// Sizes that differ between the quick and the paper suite.
struct Scale {
    sim_seconds: f64,
    sim_scale: f64,
    rotation_levels: &'static [f64],
    translation_levels: &'static [f64],
    seeds: u64,
    trajectories: &'static [TrajectoryKind],
    unical: UnicalSettings,
    /// UniCal on the real drive (full-size images: a smaller camera scale).
    unical_log: UnicalSettings,
    edge: Method,
    /// The pipeline as the perturbation protocol runs it.
    pipeline: crate::pipeline::PipelineConfig,
    ablations: &'static [&'static str],
    /// Run the correspondence ablation (Table A9) on the recorded drive as well.
    correspondence_on_log: bool,
}

impl Suite {
    /// Smoke-scale protocols, ≤ 10 minutes on two cores (release build).
    pub fn quick(pandaset: Option<PathBuf>) -> Self {
        let unical = UnicalSettings {
            iterations: 120,
            geometry_init_steps: 30,
            geometry_init_rays: 2048,
            pose_warmup: 40,
            pose_ramp: 0,
            rays_per_sensor: 256,
            rays_per_camera: 32,
            sweeps_per_lidar: 3,
            camera_frames: 2,
            camera_scale: 0.25,
            newton_lidar_poses: false,
            lidar_supervision: true,
            alignment: AlignmentLoss::SurfaceAlignment,
        };
        Self::build(
            "quick",
            Scale {
                sim_seconds: 2.0,
                sim_scale: 0.25,
                rotation_levels: &[2.0],
                translation_levels: &[20.0],
                seeds: 2,
                trajectories: &[
                    TrajectoryKind::Straight,
                    TrajectoryKind::Circle,
                    TrajectoryKind::Figure8,
                ],
                unical_log: UnicalSettings {
                    camera_frames: 1,
                    camera_scale: 0.0625,
                    ..unical.clone()
                },
                unical,
                edge: Method::Edge {
                    frames: 2,
                    max_steps: 60,
                },
                pipeline: crate::pipeline::PipelineConfig {
                    quality: crate::pipeline::Quality::Fast,
                    iterations: Some(120),
                    ..Default::default()
                },
                ablations: &["no geometry initialisation"],
                correspondence_on_log: false,
            },
            pandaset,
        )
    }

    /// The paper's protocols at full length (hours on two cores: the suite's report records
    /// each run's wall time).
    pub fn paper(pandaset: Option<PathBuf>) -> Self {
        // UniCal's own defaults (stated once, in DepthCalibConfig) at the paper quality's steps
        // and scale.
        let d = crate::unical::depth_calib::DepthCalibConfig::default();
        let paper = crate::pipeline::Quality::Paper.preset();
        let unical = UnicalSettings {
            iterations: paper.iterations,
            geometry_init_steps: d.geometry_init_steps,
            geometry_init_rays: d.geometry_init_rays,
            pose_warmup: d.pose_warmup,
            pose_ramp: d.pose_ramp,
            rays_per_sensor: d.rays_per_sensor,
            rays_per_camera: d.rays_per_camera,
            sweeps_per_lidar: 8,
            camera_frames: 4,
            camera_scale: paper.image_scale,
            newton_lidar_poses: false,
            lidar_supervision: true,
            alignment: d.alignment,
        };
        Self::build(
            "paper",
            Scale {
                sim_seconds: 8.0,
                sim_scale: 0.5,
                rotation_levels: &[2.0, 5.0, 10.0],
                translation_levels: &[20.0, 50.0, 100.0],
                seeds: 10,
                trajectories: &[
                    TrajectoryKind::Straight,
                    TrajectoryKind::Circle,
                    TrajectoryKind::SCurve,
                    TrajectoryKind::Figure8,
                    TrajectoryKind::Flower,
                ],
                unical_log: UnicalSettings {
                    camera_scale: 0.125,
                    ..unical.clone()
                },
                unical,
                edge: Method::Edge {
                    frames: 4,
                    max_steps: 300,
                },
                pipeline: crate::pipeline::PipelineConfig::default(),
                ablations: &["no geometry initialisation", "preconditioned LiDAR poses"],
                correspondence_on_log: true,
            },
            pandaset,
        )
    }

    fn build(name: &str, s: Scale, pandaset: Option<PathBuf>) -> Self {
        let sim = |scene, trajectory| DriveSpec::Sim {
            scene,
            trajectory,
            seconds: s.sim_seconds,
            scale: s.sim_scale,
            seed: 7,
        };
        let urban = sim(SceneKind::Urban, TrajectoryKind::Figure8);
        let unical = Method::UniCal(s.unical.clone());
        let case =
            |protocol, row: String, method: &Method, drive: &DriveSpec, deg, cm, seed| Case {
                protocol,
                row,
                method: method.clone(),
                drive: drive.clone(),
                perturb_deg: deg,
                perturb_cm: cm,
                seed,
            };
        let mut cases = Vec::new();
        let levels = s
            .rotation_levels
            .iter()
            .map(|d| (format!("Rotation {d}°"), *d, 0.0))
            .chain(
                s.translation_levels
                    .iter()
                    .map(|c| (format!("Transl {c} cm"), 0.0, *c)),
            );
        let pipeline = Method::Pipeline(Box::new(s.pipeline.clone()));
        for (row, deg, cm) in levels {
            for method in [&pipeline, &unical, &s.edge] {
                for seed in 1..=s.seeds {
                    cases.push(case(
                        Protocol::Perturbation,
                        row.clone(),
                        method,
                        &urban,
                        deg,
                        cm,
                        seed,
                    ));
                }
            }
        }
        // The other studies start every sensor 1° / 10 cm off (the paper's PandaSet setting).
        let (deg, cm) = (1.0, 10.0);
        for t in s.trajectories {
            let drive = sim(SceneKind::Urban, *t);
            let row = t.as_str().to_string();
            cases.push(case(Protocol::Trajectory, row, &unical, &drive, deg, cm, 1));
        }
        let featureless = sim(SceneKind::Featureless, TrajectoryKind::Figure8);
        for method in [&unical, &s.edge] {
            let row = "featureless, figure8".to_string();
            cases.push(case(
                Protocol::Featureless,
                row,
                method,
                &featureless,
                deg,
                cm,
                1,
            ));
        }
        let lidar_only = Method::UniCal(UnicalSettings {
            camera_frames: 0,
            ..s.unical.clone()
        });
        let camera_only = Method::UniCal(UnicalSettings {
            lidar_supervision: false,
            geometry_init_steps: 0,
            ..s.unical.clone()
        });
        let subsets = [
            ("Full", &unical),
            ("Camera-only", &camera_only),
            ("LiDAR-only", &lidar_only),
        ];
        for (row, method) in subsets {
            cases.push(case(
                Protocol::Sensors,
                row.into(),
                method,
                &urban,
                deg,
                cm,
                1,
            ));
        }
        cases.push(case(
            Protocol::Ablation,
            "full".into(),
            &unical,
            &urban,
            deg,
            cm,
            1,
        ));
        for ablation in s.ablations {
            let settings = match *ablation {
                "no geometry initialisation" => UnicalSettings {
                    geometry_init_steps: 0,
                    ..s.unical.clone()
                },
                _ => UnicalSettings {
                    newton_lidar_poses: true,
                    ..s.unical.clone()
                },
            };
            let method = Method::UniCal(settings);
            cases.push(case(
                Protocol::Ablation,
                ablation.to_string(),
                &method,
                &urban,
                deg,
                cm,
                1,
            ));
        }
        // Table A9: the same run with each correspondence term.
        let a9 = |cases: &mut Vec<Case>, base: &UnicalSettings, drive: &DriveSpec, suffix: &str| {
            for alignment in [
                AlignmentLoss::None,
                AlignmentLoss::ProjectedRayDistance,
                AlignmentLoss::SurfaceAlignment,
            ] {
                let method = Method::UniCal(UnicalSettings {
                    alignment,
                    ..base.clone()
                });
                let row = format!("{}{suffix}", alignment.label());
                cases.push(case(
                    Protocol::Correspondence,
                    row,
                    &method,
                    drive,
                    deg,
                    cm,
                    1,
                ));
            }
        };
        a9(&mut cases, &s.unical, &urban, "");
        if let Some(dir) = pandaset {
            let drive = DriveSpec::Log {
                mcap: dir.join("pandaset-002.mcap"),
                ground_truth: dir.join("ground_truth.json"),
            };
            if s.correspondence_on_log {
                a9(&mut cases, &s.unical_log, &drive, " (pandaset-002)");
            }
            for method in [&Method::UniCal(s.unical_log.clone()), &s.edge] {
                let row = "pandaset-002".to_string();
                cases.push(case(Protocol::PandaSet, row, method, &drive, deg, cm, 1));
            }
        }
        Self {
            name: name.into(),
            cases,
        }
    }

    /// Keep `seeds` seeds per perturbation level (at least one).
    pub fn with_seeds(mut self, seeds: u64) -> Self {
        self.cases
            .retain(|c| c.protocol != Protocol::Perturbation || c.seed <= seeds.max(1));
        self
    }

    /// Distinct runs, in order of first appearance.
    pub fn runs(&self) -> Vec<&Case> {
        let mut seen = std::collections::HashSet::new();
        self.cases.iter().filter(|c| seen.insert(c.key())).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shared_runs_run_once_and_seeds_can_be_cut() {
        let quick = Suite::quick(None);
        let runs = quick.runs();
        assert!(runs.len() < quick.cases.len(), "figure8 1°/10 cm is shared");
        let keys: std::collections::HashSet<_> = runs.iter().map(|c| c.key()).collect();
        assert_eq!(keys.len(), runs.len());
        let perturbation = |s: &Suite| {
            s.cases
                .iter()
                .filter(|c| c.protocol == Protocol::Perturbation)
                .count()
        };
        assert_eq!(
            perturbation(&quick),
            2 * 3 * 2,
            "2 levels × 3 methods (pipeline, UniCal, edge) × 2 seeds"
        );
        assert_eq!(perturbation(&quick.clone().with_seeds(1)), 6);
        let paper = Suite::paper(Some(PathBuf::from("p")));
        assert_eq!(perturbation(&paper), 6 * 3 * 10);
        assert!(paper.cases.iter().any(|c| c.protocol == Protocol::PandaSet));
        let on_log = |s: &Suite| {
            s.cases
                .iter()
                .filter(|c| c.protocol == Protocol::Correspondence)
                .filter(|c| matches!(c.drive, DriveSpec::Log { .. }))
                .count()
        };
        assert_eq!(on_log(&paper), 3, "Table A9 on PandaSet in the paper suite");
        assert_eq!(on_log(&Suite::quick(Some(PathBuf::from("p")))), 0);
    }
}
