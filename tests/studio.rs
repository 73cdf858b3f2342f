#![cfg(feature = "app")]
#![allow(clippy::unwrap_used, clippy::expect_used)]
//! The real studio, headless (egui_kittest on Mesa's software Vulkan): open the real PandaSet
//! drive, edit an extrinsic and see the overlay move in the rendered picture, start and stop the
//! optimiser, survive a bad file; occlusion, colour modes, accumulation, the camera grid, the
//! hover readout, axis locks, blink, sessions and export.

use std::path::PathBuf;
use std::time::Duration;

use egui_kittest::Harness;
use egui_kittest::kittest::{NodeT, Queryable};
use glam::DVec3;
use rigcal::app::{Studio, new_studio};
use rigcal::unical::calibrator::{LOADING_IMAGES, MATCHING};

fn pandaset() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data/pandaset-002/pandaset-002.mcap")
}

/// The studio on `log`, after its background work (the trajectory map) has landed, so
/// pictures taken later differ only by what a test changes.
fn harness(log: PathBuf) -> Harness<'static, Studio> {
    let mut h = Harness::builder()
        .with_size([1600.0, 1000.0])
        .wgpu()
        .build_eframe(move |cc| new_studio(cc, Some(log), None));
    let t0 = std::time::Instant::now();
    while h.state().drive.is_some()
        && h.state().trajectory_panel.map.is_none()
        && t0.elapsed().as_secs() < 60
    {
        h.step();
        std::thread::sleep(Duration::from_millis(20));
    }
    h
}

/// Run frames until `done` holds (the optimiser works on its own thread).
fn run_until(h: &mut Harness<'static, Studio>, secs: f64, done: impl Fn(&Studio) -> bool) -> bool {
    let t0 = std::time::Instant::now();
    while t0.elapsed().as_secs_f64() < secs {
        h.step();
        if done(h.state()) {
            return true;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    false
}

fn changed_pixels(a: &image::RgbaImage, b: &image::RgbaImage) -> usize {
    a.pixels().zip(b.pixels()).filter(|(p, q)| p != q).count()
}

#[test]
fn editing_an_extrinsic_moves_the_overlay() {
    let mut h = harness(pandaset());
    h.run_steps(4);
    assert!(h.state().drive.is_some(), "{:?}", h.state().status);
    assert!(h.state().gpu, "the wgpu paint callback should be installed");
    let (transforms, _) = h.state().overlay_state();
    assert!(!transforms.is_empty(), "the overlay has no transforms");
    let before_t = transforms.to_vec();
    let before = h.render().unwrap();
    // Rotate the shown camera by 1° about its vertical axis.
    let camera = h.state().current.cameras().next().unwrap().name.clone();
    let t = h
        .state()
        .current
        .sensor(&camera)
        .unwrap()
        .vehicle_from_sensor;
    h.state_mut().set_extrinsic(
        &camera,
        t.perturbed_right(DVec3::new(0.0, 1f64.to_radians(), 0.0), DVec3::ZERO),
    );
    h.run_steps(2);
    let after_t = h.state().overlay_state().0.to_vec();
    assert_ne!(before_t, after_t, "transforms did not follow the edit");
    let after = h.render().unwrap();
    let moved = changed_pixels(&before, &after);
    assert!(moved > 5_000, "only {moved} pixels changed after a 1° edit");
    // Undo brings the same overlay back (only the Undo/Redo buttons' look differs).
    h.state_mut().undo();
    h.run_steps(2);
    assert_eq!(h.state().overlay_state().0, &before_t[..]);
    let undone = changed_pixels(&before, &h.render().unwrap());
    assert!(
        undone < moved / 5,
        "{undone} pixels differ after undo ({moved} after the edit)"
    );
}

#[test]
fn the_optimiser_starts_publishes_and_stops() {
    let mut h = harness(pandaset());
    h.state_mut().optimiser.method = rigcal::app::optimiser::Method::EdgeAlign;
    h.run_steps(2);
    h.get_by_label("Start").click();
    h.run_steps(1);
    assert!(
        h.state().optimiser.run.is_some(),
        "clicking Start did not start a run"
    );
    assert!(
        run_until(&mut h, 120.0, |s| s.optimiser.progress.0 > 0),
        "no packet from the optimiser: {:?}",
        s_status(&h)
    );
    // While it runs it owns the rig: an edit or an undo is refused with a word, not lost.
    if h.state().optimiser.run.is_some() {
        let (undo_before, name) = (
            h.state().undo.len(),
            h.state().current.sensors[0].name.clone(),
        );
        h.state_mut()
            .set_extrinsic(&name, rigcal::geometry::Rigid::IDENTITY);
        h.state_mut().undo();
        assert_eq!(h.state().undo.len(), undo_before);
        assert!(
            h.state()
                .status
                .last()
                .unwrap()
                .contains("the optimiser is running"),
            "{:?}",
            s_status(&h)
        );
    }
    // Stop (if it has not converged already) and wait for the end.
    if h.state().optimiser.run.is_some() {
        h.get_by_label("Stop").click();
    }
    assert!(run_until(&mut h, 60.0, |s| s.optimiser.run.is_none()));
    assert!(!h.state().optimiser.history.is_empty());
    assert!(
        h.state()
            .optimiser
            .history
            .iter()
            .all(|(_, losses)| !losses.is_empty()),
        "the Stop packet's empty losses are not history"
    );
    assert!(
        h.state()
            .status
            .iter()
            .all(|s| !s.starts_with("error") || s.contains("the optimiser is running")),
        "{:?}",
        s_status(&h)
    );
}

fn s_status(h: &Harness<'static, Studio>) -> Vec<String> {
    h.state().status.clone()
}

#[test]
fn a_truncated_log_is_an_error_in_the_ui_and_the_studio_keeps_its_drive() {
    let mut h = harness(pandaset());
    h.run_steps(2);
    let dir = std::env::temp_dir().join(format!("rigcal-studio-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let bad = dir.join("truncated.mcap");
    let bytes = std::fs::read(pandaset()).unwrap();
    std::fs::write(&bad, &bytes[..4096]).unwrap();
    h.state_mut().open_log(&bad);
    h.run_steps(2);
    let last = h.state().status.last().cloned().unwrap_or_default();
    assert!(
        last.starts_with("error") && last.contains("truncated.mcap"),
        "{last}"
    );
    assert!(h.state().drive.is_some(), "the open drive was lost");
    let bad_yaml = dir.join("missing-fields.yaml");
    std::fs::write(&bad_yaml, "rigcal_calibration: 1\nsensors:\n  - name: x\n").unwrap();
    let before = h.state().current.clone();
    h.state_mut().load_calibration(&bad_yaml);
    h.run_steps(1);
    assert!(h.state().status.last().unwrap().starts_with("error"));
    assert_eq!(
        h.state().current,
        before,
        "a bad calibration file changed the rig"
    );
    // A transform typed or pasted that is not finite, or puts a sensor 1000 km out, is refused:
    // the rig could be neither saved nor autosaved.
    let name = before.sensors[0].name.clone();
    for t in [
        rigcal::geometry::Rigid::new(glam::DQuat::IDENTITY, DVec3::new(f64::NAN, 0.0, 0.0)),
        rigcal::geometry::Rigid::new(glam::DQuat::IDENTITY, DVec3::new(1e6, 0.0, 0.0)),
    ] {
        h.state_mut().set_extrinsic(&name, t);
        assert!(h.state().status.last().unwrap().starts_with("error"));
        assert_eq!(h.state().current, before);
    }
    let _ = std::fs::remove_dir_all(dir);
}

/// A log opened while the demo is still being generated is not replaced by the demo when it
/// is ready.
#[test]
fn opening_a_log_cancels_the_demo() {
    let mut studio = Studio::default();
    let dir = std::env::temp_dir().join(format!("rigcal-demo-cancel-{}", std::process::id()));
    // A small drive: the simulator finishes it in the background whatever happens.
    let mut cfg = rigcal::sim::demo::demo_config();
    cfg.rig.cameras.truncate(1);
    cfg.duration_secs = 1.0;
    rigcal::app::demo::start_in(&mut studio, dir, cfg);
    assert!(studio.demo.is_some());
    studio.open_log(&pandaset());
    assert!(studio.demo.is_none(), "{:?}", studio.status);
    assert_eq!(studio.drive.as_ref().unwrap().path(), pandaset());
}

fn rendered_difference(
    h: &mut Harness<'static, Studio>,
    change: impl FnOnce(&mut Studio),
) -> usize {
    let before = h.render().unwrap();
    change(h.state_mut());
    h.run_steps(3);
    changed_pixels(&before, &h.render().unwrap())
}

#[test]
fn occlusion_colour_modes_and_accumulation_change_what_is_drawn() {
    let mut h = harness(pandaset());
    h.run_steps(4);
    let off = rendered_difference(&mut h, |s| s.overlay.occlusion = false);
    assert!(
        off > 2_000,
        "turning occlusion off changed only {off} pixels"
    );
    let on = rendered_difference(&mut h, |s| s.overlay.occlusion = true);
    assert!(on > 2_000, "turning occlusion on changed only {on} pixels");
    use rigcal::app::state::ColorBy;
    for mode in [
        ColorBy::Height,
        ColorBy::Lidar,
        ColorBy::Intensity,
        ColorBy::Range,
    ] {
        let d = rendered_difference(&mut h, |s| s.overlay.color_by = mode);
        assert!(d > 5_000, "colour by {mode:?} changed only {d} pixels");
    }
    let before = h.state().overlay_transforms(0).len();
    let d = rendered_difference(&mut h, |s| s.overlay.accumulate = 2);
    let after = h.state().overlay_transforms(0).len();
    assert!(after > before, "accumulating sweeps added no transforms");
    assert!(d > 5_000, "accumulating sweeps changed only {d} pixels");
    // A rolling shutter, halfway through the drive (frame 8 of 16, about 2.5 m/s): 33 camera
    // poses per firing-time bucket, and the points move.
    let frame = rendered_difference(&mut h, |s| s.frame = 8);
    assert!(frame > 5_000, "frame 8 changed only {frame} pixels");
    let global = h.state().overlay_transforms(0).len();
    // A readout of no length first (one pose per bucket): the setting's fields appear, so the
    // next picture differs from this one by the points alone.
    let d = rendered_difference(&mut h, |s| s.camera_readout_ms = Some((0.0, 0.0)));
    assert_eq!(h.state().overlay_transforms(0).len(), global);
    assert!(d > 500, "the readout's fields changed only {d} pixels");
    let d = rendered_difference(&mut h, |s| s.camera_readout_ms = Some((-30.0, 10.0)));
    assert_eq!(h.state().overlay_transforms(0).len(), global * 33);
    eprintln!("a rolling shutter changed {d} pixels");
    assert!(d > 2_000, "a rolling shutter changed only {d} pixels");
    assert!(
        s_status(&h).iter().all(|m| !m.starts_with("error")),
        "{:?}",
        s_status(&h)
    );
}

#[test]
fn the_camera_grid_draws_every_camera_and_hover_reads_out_depth() {
    let mut h = harness(pandaset());
    h.run_steps(4);
    // Hovering the image reads out u, v and the depth of a LiDAR point near the cursor.
    let rect = h.state().image_rect.expect("the image was drawn");
    let mut found = None;
    for k in 0..40 {
        let pos = egui::pos2(
            rect.left() + rect.width() * (0.1 + 0.02 * k as f32),
            rect.top() + rect.height() * 0.62,
        );
        h.hover_at(pos);
        h.run_steps(2);
        if let Some(hv) = h.state().hover.clone()
            && hv.point.is_some()
        {
            found = Some(hv);
            break;
        }
    }
    let hv = found.expect("no LiDAR point under the cursor anywhere along a row");
    let (depth, lidar) = hv.point.unwrap();
    assert!(depth > 0.5 && depth < 200.0, "{depth}");
    assert!(!lidar.is_empty());
    assert!(hv.u >= 0.0 && hv.v >= 0.0);
    // The grid: every camera gets its overlay.
    let n = h.state().current.cameras().count();
    h.state_mut().grid = true;
    h.run_steps(4);
    for i in 0..n {
        assert!(
            !h.state().overlay_transforms(i).is_empty(),
            "camera {i} has no overlay in the grid"
        );
    }
}

#[test]
fn axis_locks_hold_against_edits_and_blink_alternates_views() {
    let mut h = harness(pandaset());
    h.run_steps(2);
    let camera = h.state().current.cameras().next().unwrap().name.clone();
    let t = h
        .state()
        .current
        .sensor(&camera)
        .unwrap()
        .vehicle_from_sensor;
    // Lock yaw: a yaw edit does nothing, an x edit still applies.
    h.state_mut()
        .locks
        .insert(camera.clone(), [false, false, false, false, false, true]);
    let yawed = rigcal::geometry::Rigid::new(
        glam::DQuat::from_rotation_z(0.05) * t.rotation,
        t.translation + DVec3::new(0.1, 0.0, 0.0),
    );
    h.state_mut().set_extrinsic(&camera, yawed);
    let now = h
        .state()
        .current
        .sensor(&camera)
        .unwrap()
        .vehicle_from_sensor;
    assert!((now.roll_pitch_yaw_rad()[2] - t.roll_pitch_yaw_rad()[2]).abs() < 1e-9);
    assert!((now.translation.x - t.translation.x - 0.1).abs() < 1e-12);
    assert_eq!(h.state().locked_axes(&camera), vec!["yaw"]);
    // Blink: the shown rig alternates between the current and the initial extrinsics.
    use rigcal::app::state::ExtrinsicsView;
    h.state_mut().blink = true;
    h.state_mut().blink_with = ExtrinsicsView::Initial;
    let mut seen = std::collections::HashSet::new();
    let t0 = std::time::Instant::now();
    while seen.len() < 2 && t0.elapsed().as_secs() < 10 {
        h.step();
        seen.insert(h.state().effective_view());
        std::thread::sleep(Duration::from_millis(50));
    }
    assert_eq!(seen.len(), 2, "blink never alternated: {seen:?}");
}

#[test]
fn a_session_restores_edits_segments_and_locks_and_export_round_trips() {
    let mut h = harness(pandaset());
    h.run_steps(2);
    let camera = h.state().current.cameras().next().unwrap().name.clone();
    let t = h
        .state()
        .current
        .sensor(&camera)
        .unwrap()
        .vehicle_from_sensor;
    h.state_mut().set_extrinsic(
        &camera,
        t.perturbed_right(DVec3::new(0.01, 0.0, 0.0), DVec3::new(0.02, 0.0, 0.0)),
    );
    let (t0, _) = h
        .state()
        .drive
        .as_ref()
        .unwrap()
        .time_range_nanos()
        .unwrap();
    h.state_mut().segments = vec![(t0, t0 + 2_000_000_000)];
    h.state_mut()
        .locks
        .insert(camera.clone(), [true, false, false, false, false, false]);
    use rigcal::app::optimiser::Method;
    h.state_mut().optimiser.method = Method::Unical;
    h.state_mut().camera_readout_ms = Some((-30.0, 10.0));
    let edited = h.state().current.clone();
    let dir = std::env::temp_dir().join(format!("rigcal-session-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("s.json");
    h.state_mut().save_session(&path);
    // Reopening the log forgets everything; restoring the session brings it back.
    let log = pandaset();
    h.state_mut().open_log(&log);
    assert_ne!(h.state().current, edited);
    h.state_mut().optimiser.method = Method::EdgeAlign;
    h.state_mut().camera_readout_ms = None;
    h.state_mut().restore_session(&path);
    h.run_steps(2);
    assert_eq!(h.state().current, edited, "{:?}", h.state().status);
    assert_eq!(h.state().segments, vec![(t0, t0 + 2_000_000_000)]);
    assert_eq!(h.state().locked_axes(&camera), vec!["x"]);
    assert_eq!(
        h.state().optimiser.method,
        Method::Unical,
        "the panel's method"
    );
    assert_eq!(h.state().camera_readout_ms, Some((-30.0, 10.0)));
    // A broken session file is an error in the UI; nothing is lost.
    std::fs::write(dir.join("bad.json"), "{").unwrap();
    h.state_mut().restore_session(&dir.join("bad.json"));
    assert!(h.state().status.last().unwrap().starts_with("error"));
    assert_eq!(h.state().current, edited);
    // Export: the document names its input and reads back to the same rig.
    use rigcal::app::state::ExtrinsicsView;
    let doc = rigcal::app::export::document(h.state(), &edited, ExtrinsicsView::Current);
    assert!(doc.provenance.contains_key("input") && doc.provenance.contains_key("time_range"));
    let date = doc.provenance.get("date").and_then(|v| v.as_str()).unwrap();
    assert!(date.len() == 10 && date.starts_with("20"), "{date}");
    let out = dir.join("export.yaml");
    doc.save(&out).unwrap();
    let back = rigcal::calib::CalibrationFile::load_rig(&out).unwrap();
    for s in &edited.sensors {
        let (r, t) = s
            .vehicle_from_sensor
            .difference(back.sensor(&s.name).unwrap().vehicle_from_sensor);
        assert!(r < 1e-12 && t < 1e-12, "{}", s.name);
    }
    let _ = std::fs::remove_dir_all(dir);
}

/// Mean rotation error (deg) of the cameras against the ground truth, root = first LiDAR.
fn camera_rotation_error_deg(s: &Studio) -> f64 {
    let gt = s.ground_truth.as_ref().unwrap();
    let root = gt.lidars().next().unwrap().name.clone();
    let errors =
        rigcal::geometry::rig_errors(&gt.extrinsics(), &s.current.extrinsics(), &root).unwrap();
    let cams: Vec<f64> = errors
        .iter()
        .filter(|e| gt.sensor(&e.sensor).is_some_and(|x| x.camera.is_some()))
        .map(|e| e.rotation_deg)
        .collect();
    cams.iter().sum::<f64>() / cams.len() as f64
}

#[test]
fn the_demo_is_generated_with_progress_opens_off_and_the_optimiser_brings_it_closer() {
    use rigcal::sim::demo::demo_config;
    // The demo's recipe with two of its cameras.
    let mut cfg = demo_config();
    cfg.rig
        .cameras
        .retain(|c| c.name == "front_camera" || c.name == "left_camera");
    cfg.duration_secs = 4.0;
    let dir = std::env::temp_dir().join(format!("rigcal-demo-test-{}", std::process::id()));
    let job_dir = dir.clone();
    let mut h = Harness::builder()
        .with_size([1600.0, 1000.0])
        .wgpu()
        .build_eframe(move |cc| {
            let mut s = rigcal::app::bare_studio(cc);
            rigcal::app::demo::start_in(&mut s, job_dir, cfg);
            s
        });
    // Progress is shown while the simulator writes the drive; then it opens with its truth.
    let mut saw_progress = false;
    let t0 = std::time::Instant::now();
    while t0.elapsed().as_secs() < 600 && h.state().drive.is_none() {
        h.step();
        if h.state().demo.as_ref().is_some_and(|j| j.progress.1 > 0) {
            saw_progress = true;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    assert!(h.state().drive.is_some(), "{:?}", h.state().status);
    assert!(saw_progress, "no progress was shown");
    assert!(h.state().ground_truth.is_some());
    h.run_steps(4);
    // The initial guess is visibly off: the ground-truth overlay differs.
    use rigcal::app::state::ExtrinsicsView;
    let initial = h.render().unwrap();
    h.state_mut().view = ExtrinsicsView::GroundTruth;
    h.run_steps(3);
    let truth = h.render().unwrap();
    assert!(changed_pixels(&initial, &truth) > 5_000);
    h.state_mut().view = ExtrinsicsView::Current;
    // The optimiser (edge alignment: seconds) brings the cameras closer to the truth.
    h.state_mut().optimiser.method = rigcal::app::optimiser::Method::EdgeAlign;
    h.run_steps(2);
    let before = camera_rotation_error_deg(h.state());
    h.get_by_label("Start").click();
    assert!(run_until(&mut h, 300.0, |s| s.optimiser.run.is_none()
        && !s.optimiser.history.is_empty()));
    let after = camera_rotation_error_deg(h.state());
    eprintln!("demo cameras: {before:.2}° -> {after:.2}°");
    assert!(after < before, "{before:.2}° -> {after:.2}°");
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn unical_with_cameras_runs_from_the_optimiser_panel() {
    use rigcal::app::optimiser::Method;
    let mut h = harness(pandaset());
    h.run_steps(2);
    h.state_mut().optimiser.method = Method::Unical;
    h.state_mut().optimiser.frames = 1;
    // Let the panel lay out with the new method before clicking.
    h.run_steps(2);
    h.get_by_label("Start").click();
    h.run_steps(1);
    assert!(
        h.state().optimiser.run.is_some(),
        "{:?} {:?}",
        s_status(&h),
        h.state().optimiser.message
    );
    // While it prepares, the panel shows a progress bar of the images loaded (and of the
    // keypoint matching when the matches are not cached yet).
    let t0 = std::time::Instant::now();
    let mut bar = None;
    while bar.is_none() && t0.elapsed().as_secs() < 120 && h.state().optimiser.progress.0 == 0 {
        h.step();
        bar = [LOADING_IMAGES, MATCHING].into_iter().find_map(|phase| {
            h.query_all_by_label_contains(phase)
                .next()
                .and_then(|node| node.accesskit_node().label())
        });
        std::thread::sleep(Duration::from_millis(10));
    }
    let bar = bar.expect("no preparation progress bar");
    eprintln!("preparation: {bar}");
    assert!(bar.contains('/'), "{bar}");
    assert!(
        run_until(&mut h, 300.0, |s| s.optimiser.progress.0 > 0),
        "no packet from UniCal: {:?}",
        s_status(&h)
    );
    let losses = h.state().optimiser.history.last().unwrap().1.clone();
    // The first iterations initialise the geometry from the LiDAR returns.
    assert!(
        !losses.is_empty() && losses.iter().all(|(_, v)| v.is_finite()),
        "{losses:?}"
    );
    h.get_by_label("Stop").click();
    assert!(run_until(&mut h, 120.0, |s| s.optimiser.run.is_none()));
    assert!(h.state().status.iter().all(|s| !s.starts_with("error")));
}

/// The hand-eye initialiser from the optimiser panel: ticked, it runs before the scene is
/// prepared and reports each camera in the status bar; on this straight drive it keeps the
/// camera and says why, and the run goes on from the same rig.
#[test]
fn the_hand_eye_runs_from_the_optimiser_panel_and_reports_each_camera() {
    use rigcal::app::optimiser::Method;
    let mut h = harness(pandaset());
    h.run_steps(2);
    h.state_mut().optimiser.method = Method::Unical;
    h.state_mut().optimiser.frames = 1;
    h.state_mut().optimiser.cameras = vec!["front_camera".into()];
    h.run_steps(2);
    h.get_by_label_contains("fit each camera to its own motion first")
        .click();
    // A rolling shutter too: the run reads the log again with the readout and says so.
    h.get_by_label("rolling-shutter cameras").click();
    h.run_steps(2);
    assert!(h.state().optimiser.hand_eye);
    assert_eq!(
        h.state().camera_readout_ms,
        Some(rigcal::app::optimiser::DEFAULT_READOUT_MS)
    );
    let before = h.state().current.clone();
    h.get_by_label("Start").click();
    h.run_steps(1);
    assert!(h.state().optimiser.run.is_some(), "{:?}", s_status(&h));
    let note = "camera hand-eye: front_camera kept: the vehicle turns at most";
    assert!(
        run_until(&mut h, 300.0, |s| s.status.iter().any(|m| m.contains(note))),
        "{:?}",
        s_status(&h)
    );
    assert!(
        s_status(&h)
            .iter()
            .any(|m| m.starts_with("rolling shutter: image rows exposed from -15.0 to +15.0 ms")),
        "{:?}",
        s_status(&h)
    );
    assert!(
        run_until(&mut h, 300.0, |s| s.optimiser.progress.0 > 0),
        "no packet from UniCal: {:?}",
        s_status(&h)
    );
    h.get_by_label("Stop").click();
    assert!(run_until(&mut h, 120.0, |s| s.optimiser.run.is_none()));
    assert!(h.state().status.iter().all(|s| !s.starts_with("error")));
    // Kept by the hand-eye; the LiDARs and the unticked cameras never move.
    let after = &h.state().current;
    for s in &before.sensors {
        if s.name != "front_camera" && s.kind != rigcal::calib::SensorKind::Lidar {
            let (r, t) = s
                .vehicle_from_sensor
                .difference(after.sensor(&s.name).unwrap().vehicle_from_sensor);
            assert!(r < 1e-9 && t < 1e-9, "{}: {r} rad, {t} m", s.name);
        }
    }
}

/// ICP from the optimiser panel: every LiDAR registered against the reference LiDAR; the run
/// ends on its own, publishes its RMSE and fitness, leaves the reference LiDAR and the cameras
/// alone and keeps the PandarGT within the reference's accuracy of the recorded calibration.
#[test]
fn icp_runs_from_the_optimiser_panel() {
    use rigcal::app::optimiser::Method;
    let mut h = harness(pandaset());
    h.run_steps(2);
    h.state_mut().optimiser.method = Method::Icp;
    h.state_mut().optimiser.frames = 1;
    h.run_steps(2);
    let before = h.state().current.clone();
    h.get_by_label("Start").click();
    h.run_steps(1);
    assert!(
        h.state().optimiser.run.is_some(),
        "{:?} {:?}",
        s_status(&h),
        h.state().optimiser.message
    );
    assert!(
        run_until(&mut h, 300.0, |s| s.optimiser.run.is_none()
            && !s.optimiser.history.is_empty()),
        "ICP did not finish: {:?}",
        s_status(&h)
    );
    let losses = h.state().optimiser.history.last().unwrap().1.clone();
    assert!(
        losses
            .iter()
            .any(|(n, v)| n.starts_with("icp rmse cm/") && v.is_finite() && *v > 0.0),
        "{losses:?}"
    );
    let after = &h.state().current;
    for s in &before.sensors {
        let (rot, trans) = s
            .vehicle_from_sensor
            .difference(after.sensor(&s.name).unwrap().vehicle_from_sensor);
        if s.camera.is_some() || s.name == before.lidars().next().unwrap().name {
            assert!(rot + trans < 1e-12, "{} moved", s.name);
        } else {
            // ICP settles ≈ 0.1° / 3.7 cm from the recorded extrinsic (tests/icp.rs): the
            // result was applied, and stays within the reference's accuracy.
            assert!(rot.to_degrees() > 0.02, "{} was not updated", s.name);
            assert!(
                rot.to_degrees() < 0.2 && trans < 0.04,
                "{}: {:.3}° {:.1} cm",
                s.name,
                rot.to_degrees(),
                trans * 100.0
            );
        }
    }
    assert!(h.state().status.iter().all(|s| !s.starts_with("error")));
}

#[test]
fn the_export_panel_writes_every_format_and_a_urdf_loads_back_as_an_undoable_edit() {
    use rigcal::app::state::Tab;
    use rigcal::interop::{ExportFormat, write};
    let mut h = harness(pandaset());
    h.state_mut().tab = Tab::Export;
    h.run_steps(2);
    let dir = std::env::temp_dir().join(format!("rigcal-studio-export-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let cameras: Vec<String> = h
        .state()
        .current
        .cameras()
        .map(|c| c.name.clone())
        .collect();
    for format in ExportFormat::ALL {
        h.state_mut().export.format = Some(format);
        // A KITTI file holds three cameras: the panel leaves the others out.
        h.state_mut().export.left_out = if format == ExportFormat::Kitti {
            cameras[3..].to_vec()
        } else {
            Vec::new()
        };
        h.run_steps(2);
        // The button says where it writes: a folder for the per-camera formats.
        let button = if format.is_directory() {
            "Save to folder…"
        } else {
            "Save…"
        };
        h.get_by_label(button);
        let export = match h.state().export.last() {
            Some(Ok(e)) => e.clone(),
            other => panic!("{}: {other:?}", format.name()),
        };
        assert_eq!(export.format, format);
        if format == ExportFormat::Kitti {
            let text = export.preview();
            assert!(
                text.starts_with("P0: ") && text.contains("\nP3: "),
                "{text}"
            );
        }
        // PandaSet's cameras are undistorted pinholes, so every format takes them.
        let out = dir.join(format.default_file_name());
        let files = write(&export, &out).unwrap();
        assert!(!files.is_empty() && files.iter().all(|f| f.metadata().unwrap().len() > 0));
    }
    // A URDF edited elsewhere comes back as one edit, and undo takes it back.
    let before = h.state().current.clone();
    let lidar = before.lidars().last().unwrap().clone();
    let mut moved = before.clone();
    moved
        .sensor_mut(&lidar.name)
        .unwrap()
        .vehicle_from_sensor
        .translation
        .z += 0.25;
    let urdf = dir.join("moved.urdf");
    let doc = rigcal::calib::CalibrationFile::from_rig(&moved);
    let e = rigcal::interop::export(&doc, ExportFormat::Urdf, &Default::default()).unwrap();
    write(&e, &urdf).unwrap();
    h.state_mut().load_calibration(&urdf);
    h.run_steps(2);
    let got = h
        .state()
        .current
        .sensor(&lidar.name)
        .unwrap()
        .vehicle_from_sensor;
    assert!((got.translation.z - lidar.vehicle_from_sensor.translation.z - 0.25).abs() < 1e-9);
    let status = h.state().status.last().unwrap().clone();
    assert!(
        status.contains("URDF") && status.contains("8 of 8"),
        "{status}"
    );
    h.state_mut().undo();
    assert_eq!(h.state().current, before);
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn mutual_information_runs_from_the_optimiser_panel_and_moves_only_its_camera() {
    use rigcal::app::optimiser::Method;
    let mut h = harness(pandaset());
    h.run_steps(2);
    h.state_mut().optimiser.method = Method::MutualInformation;
    h.state_mut().optimiser.frames = 1;
    h.state_mut().optimiser.cameras = vec!["front_camera".into()];
    h.run_steps(2);
    let before = h.state().current.clone();
    h.get_by_label("Start").click();
    h.run_steps(1);
    assert!(
        run_until(&mut h, 300.0, |s| s.optimiser.run.is_none()
            && !s.optimiser.history.is_empty()),
        "MI did not finish: {:?}",
        s_status(&h)
    );
    let losses = h.state().optimiser.history.last().unwrap().1.clone();
    assert!(
        losses
            .iter()
            .any(|(n, v)| n == "mi_nats/front_camera" && v.is_finite() && *v > 0.0),
        "{losses:?}"
    );
    for s in &before.sensors {
        let (rot, trans) = s.vehicle_from_sensor.difference(
            h.state()
                .current
                .sensor(&s.name)
                .unwrap()
                .vehicle_from_sensor,
        );
        if s.name == "front_camera" {
            // Within the paper's bounds: ±2° and ±20 cm per axis.
            assert!(rot.to_degrees() < 3.5 && trans < 0.35, "{rot} {trans}");
        } else {
            assert!(rot + trans < 1e-12, "{} moved", s.name);
        }
    }
    assert!(h.state().status.iter().all(|s| !s.starts_with("error")));
}

#[test]
fn the_checkerboard_method_runs_from_the_optimiser_panel_and_says_when_there_are_no_boards() {
    use rigcal::app::optimiser::Method;
    // PandaSet has no checkerboards: the run ends with a one-line reason naming the pair.
    let mut h = harness(pandaset());
    h.run_steps(2);
    h.state_mut().optimiser.method = Method::Target;
    h.state_mut().optimiser.frames = 1;
    h.state_mut().optimiser.cameras = vec!["front_camera".into()];
    h.run_steps(2);
    let before = h.state().current.clone();
    h.get_by_label("Start").click();
    h.run_steps(1);
    assert!(
        run_until(&mut h, 300.0, |s| s.optimiser.run.is_none()),
        "the checkerboard run did not end: {:?}",
        s_status(&h)
    );
    let message = h.state().optimiser.message.clone().unwrap_or_default();
    assert!(
        message.starts_with("error")
            && message.contains("front_camera")
            && message.contains("checkerboard"),
        "{message}"
    );
    assert_eq!(h.state().current, before);
}

/// File ▸ Open, Open recent and drag and drop open a log on a worker: the window keeps
/// drawing, the log is installed when ready, and a bad file is an error that leaves the open
/// drive alone.
#[test]
fn a_log_opens_in_the_background() {
    let mut studio = Studio::default();
    let ctx = egui::Context::default();
    let wait = |studio: &mut Studio| {
        let t0 = std::time::Instant::now();
        while studio.opening.is_some() && t0.elapsed().as_secs() < 60 {
            studio.poll_opening(&ctx);
            std::thread::sleep(Duration::from_millis(20));
        }
    };
    studio.open_log_in_background(&pandaset());
    assert!(studio.drive.is_none() && studio.opening.is_some());
    wait(&mut studio);
    assert_eq!(
        studio.drive.as_ref().map(|d| d.path().to_path_buf()),
        Some(pandaset()),
        "{:?}",
        studio.status
    );
    let dir = std::env::temp_dir().join(format!("rigcal-bg-open-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let bad = dir.join("not-a-log.mcap");
    std::fs::write(&bad, "hello").unwrap();
    studio.open_any(bad);
    wait(&mut studio);
    let last = studio.status.last().unwrap();
    assert!(
        last.starts_with("error") && last.contains("not-a-log.mcap"),
        "{last}"
    );
    assert_eq!(studio.drive.as_ref().unwrap().path(), pandaset());
    let _ = std::fs::remove_dir_all(dir);
}

/// A small simulated drive with turns: both LiDARs and the front camera, 2° / 20 cm off.
fn small_drive() -> (tempfile::TempDir, PathBuf) {
    use rigcal::sim::rigs::{RigPreset, SimRig};
    use rigcal::sim::synth::{SynthConfig, synthesize};
    let tmp = tempfile::Builder::new()
        .prefix("rigcal-studio-pipeline-")
        .tempdir()
        .unwrap();
    let mut rig = SimRig::preset(RigPreset::Pandaset);
    rig.cameras.retain(|c| c.name == "front_camera");
    let mut cfg = SynthConfig::new(
        rigcal::sim::world::SceneKind::Urban,
        rig,
        rigcal::sim::trajectories::TrajectoryKind::Circle,
        4.0,
        35,
    );
    cfg.scale = 0.25;
    cfg.camera_rate_hz = 2.0;
    cfg.perturb_deg = 2.0;
    cfg.perturb_cm = 20.0;
    let log = tmp.path().join("drive.mcap");
    synthesize(&cfg, &log, &tmp.path().join("gt.yaml"), &mut |_, _| {}).unwrap();
    (tmp, log)
}

/// "Calibrate everything" is the panel's first method, plans as `rigcal calibrate` does from
/// the same drive, and runs: the plan reaches the status bar, the LiDARs registered while it
/// prepares move the overlay, and the loss curves fill.
#[test]
fn calibrate_everything_runs_the_clis_plan_from_the_optimiser_panel() {
    use rigcal::app::optimiser::{Method, pipeline_config, pipeline_request};
    let (_tmp, log) = small_drive();
    let mut h = harness(log.clone());
    assert_eq!(h.state().optimiser.method, Method::Pipeline);
    h.run_steps(2);
    // The CLI's configuration for this drive, as `--print-config` prints it, and the studio's
    // give one plan.
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_rigcal"))
        .args(["calibrate", "--print-config"])
        .output()
        .unwrap();
    assert!(out.status.success());
    let cli = rigcal::pipeline::PipelineConfig::from_yaml(
        &String::from_utf8_lossy(&out.stdout),
        "stdout",
    )
    .unwrap();
    let studio_config = pipeline_config(h.state());
    assert_eq!(studio_config, cli);
    let drive = h.state().drive.clone().unwrap();
    let plan = |config: &rigcal::pipeline::PipelineConfig, request| {
        rigcal::pipeline::Plan::build(&drive, &drive.rig, request, config).unwrap()
    };
    let cli_request = rigcal::pipeline::PlanRequest::default();
    assert_eq!(
        plan(&studio_config, &pipeline_request(h.state())),
        plan(&cli, &cli_request)
    );
    let start = h.state().current.clone();
    let before = h.render().unwrap();
    h.get_by_label("Start").click();
    h.run_steps(1);
    assert!(h.state().optimiser.run.is_some(), "{:?}", s_status(&h));
    assert!(
        run_until(&mut h, 300.0, |s| s.optimiser.history.len() >= 3),
        "no losses from the pipeline: {:?} {:?}",
        s_status(&h),
        h.state().optimiser.message
    );
    let status = s_status(&h).join("\n");
    assert!(
        status.contains("plan: lidars: pandar64 (the reference) fitted"),
        "{status}"
    );
    // The LiDARs were registered before UniCal: the overlay draws the moved rig.
    assert_ne!(h.state().current, start);
    h.run_steps(3);
    let after = h.render().unwrap();
    assert!(changed_pixels(&before, &after) > 500);
    let losses = &h.state().optimiser.history.last().unwrap().1;
    assert!(losses.iter().all(|(_, v)| v.is_finite()), "{losses:?}");
    h.get_by_label("Stop").click();
    assert!(run_until(&mut h, 120.0, |s| s.optimiser.run.is_none()));
    assert!(
        h.state().status.iter().all(|s| !s.starts_with("error")),
        "{:?}",
        s_status(&h)
    );
}
