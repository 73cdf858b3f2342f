#![allow(clippy::unwrap_used, clippy::expect_used)]
//! Correspondences and the surface alignment term on the real PandaSet drive, from known
//! answers: matched pixels of overlapping camera frames agree with the reference calibration
//! (their two rays, under the true extrinsics and trajectory, meet to within a few pixels), and
//! with every other loss switched off the alignment term alone moves the cameras (and only with
//! it on).

mod common;

use rigcal::calib::Rig;
use rigcal::log::Drive;
use rigcal::optim::runner::Calibrator;
use rigcal::unical::calibrator::{LOADING_IMAGES, MATCHING, UnicalLidarStage};
use rigcal::unical::depth_calib::DepthCalibConfig;
use rigcal::unical::pose::PoseParams;
use rigcal::unical::surface_align::{
    AlignCamera, AlignRay, AlignSettings, AlignmentLoss, projected_ray_distance,
};

use common::{pandaset_dir as pandaset, reference_rig};

fn stage(drive: &Drive, rig: &Rig, config: DepthCalibConfig) -> UnicalLidarStage {
    stage_reporting(drive, rig, config).0
}

/// The stage and every progress report of its preparation, in order.
fn stage_reporting(
    drive: &Drive,
    rig: &Rig,
    config: DepthCalibConfig,
) -> (UnicalLidarStage, Vec<(String, usize, usize)>) {
    let reports = std::sync::Mutex::new(Vec::new());
    let stage = UnicalLidarStage::from_drive(drive, rig, 1, &[], config)
        .unwrap()
        .with_cameras_reporting(drive, 2, &[], 0.25, &|phase, done, total| {
            reports
                .lock()
                .unwrap()
                .push((phase.to_owned(), done, total))
        })
        .unwrap();
    (stage, reports.into_inner().unwrap())
}

/// The reports of one phase.
fn phase(reports: &[(String, usize, usize)], name: &str) -> Vec<(usize, usize)> {
    reports
        .iter()
        .filter(|r| r.0 == name)
        .map(|r| (r.1, r.2))
        .collect()
}

#[test]
fn matches_agree_with_the_reference_calibration() {
    let drive = Drive::open(&pandaset().join("pandaset-002.mcap")).unwrap();
    let rig = reference_rig(&drive);
    // The cache folder is made by the stage, inside a scratch folder removed when dropped.
    let tmp = tempfile::Builder::new()
        .prefix("rigcal-matches-")
        .tempdir()
        .unwrap();
    let cache = tmp.path().join("cache");
    let config = DepthCalibConfig {
        iterations: 1,
        geometry_init_steps: 0,
        alignment: AlignmentLoss::SurfaceAlignment,
        correspondence_cache: Some(cache.clone()),
        ..DepthCalibConfig::default()
    };
    let (s, reports) = stage_reporting(&drive, &rig, config.clone());
    let calib = s.calibration();
    let c = &calib.correspondences;
    // Progress: every image loaded is counted, then every candidate pair matched, each phase
    // from 0 to its total.
    let images = phase(&reports, LOADING_IMAGES);
    let n_images = 2 * drive.rig.cameras().count();
    assert_eq!(images.first(), Some(&(0, n_images)), "{reports:?}");
    assert_eq!(images.last(), Some(&(n_images, n_images)));
    assert_eq!(images.len(), n_images + 1);
    let matching = phase(&reports, MATCHING);
    assert_eq!(matching.first(), Some(&(0, c.candidates)));
    assert_eq!(matching.len(), c.candidates + 1);
    let mut counted: Vec<usize> = matching.iter().map(|m| m.0).collect();
    counted.sort_unstable();
    assert_eq!(counted, (0..=c.candidates).collect::<Vec<_>>());
    let last = reports.iter().rposition(|r| r.0 == LOADING_IMAGES).unwrap();
    assert!(
        reports.iter().position(|r| r.0 == MATCHING).unwrap() > last,
        "matching reported before the images were loaded"
    );
    // Matched once: the cache file is written, read back by the next run, and a damaged file
    // is rebuilt to the same answer.
    let files: Vec<_> = std::fs::read_dir(&cache).unwrap().flatten().collect();
    assert_eq!(files.len(), 1, "one cache file");
    let (again, reports) = stage_reporting(&drive, &rig, config.clone());
    assert_eq!(&again.calibration().correspondences, c);
    // Read back from the cache: the matching is reported done at once.
    assert_eq!(
        phase(&reports, MATCHING),
        vec![(c.candidates, c.candidates)]
    );
    // The next run reads the file: emptied of pairs, it gives no pairs.
    let text = std::fs::read_to_string(files[0].path()).unwrap();
    let mut doc: serde_json::Value = serde_json::from_str(&text).unwrap();
    doc["pairs"] = serde_json::json!([]);
    std::fs::write(files[0].path(), doc.to_string()).unwrap();
    let emptied = stage(&drive, &rig, config.clone());
    assert!(emptied.calibration().correspondences.pairs.is_empty());
    std::fs::write(files[0].path(), b"{ not json").unwrap();
    let rebuilt = stage(&drive, &rig, config.clone());
    assert_eq!(&rebuilt.calibration().correspondences, c);
    assert!(c.candidates > 0, "no overlapping frames");
    assert!(
        !c.pairs.is_empty(),
        "no verified pair among {}",
        c.candidates
    );
    assert!(c.matches() >= 50, "{} matches", c.matches());
    let names: Vec<String> = drive.rig.cameras().map(|c| c.name.clone()).collect();
    assert!(
        c.pairs.iter().any(|p| p.a.0 != p.b.0),
        "a pair of two different cameras"
    );
    // Under the reference calibration each match's two rays meet: their closest points project
    // back within a few (training) pixels of the matched keypoints.
    let extrinsics = calib.extrinsics();
    let mut errors = Vec::new();
    for pair in &c.pairs {
        let cam = |k: usize| {
            let name = &names[k];
            let pose =
                PoseParams::from_rigid(extrinsics.iter().find(|(n, _)| n == name).unwrap().1);
            (pose, calib.camera_intrinsics(name).unwrap().clone())
        };
        let ((pa, ka), (pb, kb)) = (cam(pair.a.0), cam(pair.b.0));
        let stamp = |(camera, frame): (usize, usize)| {
            let stream = drive.stream(&names[camera]).unwrap();
            let usable = drive.frames_within(&names[camera], &[]);
            let index = rigcal::log::spread_evenly(&usable, 2)[frame];
            stream.frames[index].stamp_nanos
        };
        let (wa, wb) = (
            drive.trajectory.world_from_vehicle(stamp(pair.a)).unwrap(),
            drive.trajectory.world_from_vehicle(stamp(pair.b)).unwrap(),
        );
        for (ua, ub) in &pair.pixels {
            let ray = |k: &rigcal::geometry::camera::CameraIntrinsics, wv, u| AlignRay {
                world_from_vehicle: wv,
                dir_in_sensor: k.unproject(u).unwrap(),
                pixel: u,
                taus_m: Vec::new(),
            };
            let (ra, rb) = (ray(&ka, wa, *ua), ray(&kb, wb, *ub));
            let cams = (
                AlignCamera {
                    pose: &pa,
                    intrinsics: &ka,
                    pixel_scale: 1.0,
                },
                AlignCamera {
                    pose: &pb,
                    intrinsics: &kb,
                    pixel_scale: 1.0,
                },
            );
            if let Some(e) = projected_ray_distance(cams, (&ra, &rb), f64::INFINITY) {
                errors.push(e.sqrt());
            }
        }
    }
    errors.sort_by(f64::total_cmp);
    let median = errors[errors.len() / 2];
    let p90 = errors[errors.len() * 9 / 10];
    eprintln!(
        "{} candidate pairs, {} verified, {} matches; against the reference: median {median:.2} px, p90 {p90:.2} px (training pixels, 480 wide)",
        c.candidates,
        c.pairs.len(),
        c.matches()
    );
    assert!(
        median < 2.0 && p90 < 6.0,
        "median {median:.2} px, p90 {p90:.2} px of {}",
        errors.len()
    );
}

/// With the colour, depth, intensity and regulariser weights at zero, only the alignment term
/// can move a camera: it does with the term on and does not with it off.
#[test]
fn the_alignment_term_alone_moves_the_cameras() {
    let drive = Drive::open(&pandaset().join("pandaset-002.mcap")).unwrap();
    let rig = reference_rig(&drive);
    let moved = |alignment| {
        let config = DepthCalibConfig {
            iterations: 2,
            geometry_init_steps: 0,
            pose_warmup: 0,
            pose_ramp: 0,
            rays_per_sensor: 64,
            rays_per_camera: 16,
            rgb_weight: 0.0,
            depth_weight: 0.0,
            intensity_weight: 0.0,
            regulariser_weight: 0.0,
            alignment,
            alignment_settings: AlignSettings {
                max_error_px: f64::INFINITY,
                min_accumulation: 0.0,
                information: false,
            },
            ..DepthCalibConfig::default()
        };
        let mut s = stage(&drive, &rig, config);
        let mut report = Vec::new();
        for _ in 0..2 {
            report = s.step().losses;
        }
        let now = s.current();
        let cameras_moved = drive
            .rig
            .cameras()
            .filter(|c| {
                let (r, t) = rig
                    .sensor(&c.name)
                    .unwrap()
                    .vehicle_from_sensor
                    .difference(now.sensor(&c.name).unwrap().vehicle_from_sensor);
                r + t > 1e-9
            })
            .count();
        (cameras_moved, report)
    };
    let (on, losses) = moved(AlignmentLoss::SurfaceAlignment);
    let alignment = losses.iter().find(|(n, _)| n == "alignment px").unwrap().1;
    assert!(alignment.is_finite() && alignment > 0.0, "{losses:?}");
    assert!(on >= 2, "{on} cameras moved");
    let (off, _) = moved(AlignmentLoss::None);
    assert_eq!(off, 0, "nothing else moves the cameras");
}

/// With an alignment release the cameras move during the geometry initialisation, on the
/// correspondence term alone, while the LiDARs wait for the warm-up; without one nothing moves
/// before it; a release that does not rotate moves only the cameras' translations.
#[test]
fn an_alignment_release_moves_only_the_cameras_during_the_geometry_initialisation() {
    let drive = Drive::open(&pandaset().join("pandaset-002.mcap")).unwrap();
    let rig = reference_rig(&drive);
    // (cameras turned, cameras shifted, LiDARs moved, summed alignment term)
    let moved = |alignment_release, alignment_release_rotates| {
        let config = DepthCalibConfig {
            iterations: 40,
            geometry_init_steps: 3,
            geometry_init_rays: 512,
            pose_warmup: 10,
            pose_ramp: 0,
            alignment_release,
            alignment_release_rotates,
            rays_per_sensor: 64,
            rays_per_camera: 16,
            alignment_settings: AlignSettings {
                max_error_px: f64::INFINITY,
                min_accumulation: 0.0,
                information: false,
            },
            ..DepthCalibConfig::default()
        };
        let mut s = stage(&drive, &rig, config);
        let mut alignment = 0.0;
        for _ in 0..3 {
            let losses = s.step().losses;
            assert!(
                losses.iter().any(|(n, _)| n.contains("init")),
                "still initialising: {losses:?}"
            );
            alignment += losses
                .iter()
                .find(|(n, _)| n == "alignment px")
                .map_or(0.0, |l| l.1);
        }
        let now = s.current();
        let count = |lidar: bool, part: fn((f64, f64)) -> f64| {
            rig.sensors
                .iter()
                .filter(|c| (c.kind == rigcal::calib::SensorKind::Lidar) == lidar)
                .filter(|c| {
                    let d = c
                        .vehicle_from_sensor
                        .difference(now.sensor(&c.name).unwrap().vehicle_from_sensor);
                    part(d) > 1e-9
                })
                .count()
        };
        let both = |(r, t): (f64, f64)| r + t;
        (
            count(false, |(r, _)| r),
            count(false, |(_, t)| t),
            count(true, both),
            alignment,
        )
    };
    let (turned, shifted, lidars, alignment) = moved(Some(1), true);
    assert!(
        turned >= 2 && shifted >= 2,
        "{turned} turned, {shifted} shifted"
    );
    assert_eq!(lidars, 0);
    assert!(alignment > 0.0);
    let (turned, shifted, lidars, _) = moved(Some(1), false);
    assert_eq!((turned, lidars), (0, 0), "translations only");
    assert!(shifted >= 2, "{shifted} cameras shifted");
    assert_eq!(moved(None, true), (0, 0, 0, 0.0));
}
