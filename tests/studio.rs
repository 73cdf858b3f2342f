#![cfg(feature = "app")]
#![allow(clippy::unwrap_used, clippy::expect_used)]
//! The real studio, headless (egui_kittest on Mesa's software Vulkan): open the real PandaSet
//! drive, edit an extrinsic and see the overlay move in the rendered picture, start and stop the
//! optimiser, and survive a bad file.

use std::path::PathBuf;
use std::time::Duration;

use egui_kittest::Harness;
use egui_kittest::kittest::Queryable;
use glam::DVec3;
use rigcal::app::{Studio, new_studio};

fn pandaset() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data/pandaset-002/pandaset-002.mcap")
}

fn harness(log: PathBuf) -> Harness<'static, Studio> {
    Harness::builder()
        .with_size([1600.0, 1000.0])
        .wgpu()
        .build_eframe(move |cc| new_studio(cc, Some(log), None))
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
    // Stop (if it has not converged already) and wait for the end.
    if h.state().optimiser.run.is_some() {
        h.get_by_label("Stop").click();
    }
    assert!(run_until(&mut h, 60.0, |s| s.optimiser.run.is_none()));
    assert!(!h.state().optimiser.history.is_empty());
    assert!(
        h.state().status.iter().all(|s| !s.starts_with("error")),
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
    let _ = std::fs::remove_dir_all(dir);
}
