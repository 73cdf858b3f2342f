#![allow(clippy::unwrap_used, clippy::expect_used)]
//! Our camera models against OpenCV's `cv2.projectPoints` / `cv2.fisheye.projectPoints`, using
//! the reference projections in `tests/fixtures/opencv/camera_projections.json` (regenerate
//! with `tests/fixtures/opencv/make_camera_fixtures.py`).

use glam::{DVec2, DVec3};
use rigcal::geometry::camera::CameraIntrinsics;
use serde::Deserialize;

const TOLERANCE_PX: f64 = 1e-6;

#[derive(Deserialize)]
struct Fixture {
    opencv_version: String,
    cases: Vec<Case>,
}

#[derive(Deserialize)]
struct Case {
    name: String,
    intrinsics: CameraIntrinsics,
    points: Vec<[f64; 3]>,
    pixels: Vec<[f64; 2]>,
}

fn fixture() -> Fixture {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/fixtures/opencv/camera_projections.json"
    );
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{path}: {e}"));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{path}: {e}"))
}

#[test]
fn projection_matches_opencv() {
    let fixture = fixture();
    assert!(fixture.cases.len() >= 7);
    let mut worst = 0.0_f64;
    for case in &fixture.cases {
        assert_eq!(case.points.len(), case.pixels.len(), "{}", case.name);
        assert!(case.points.len() >= 40, "{}", case.name);
        for (p, expected) in case.points.iter().zip(&case.pixels) {
            let (p, expected) = (DVec3::from_array(*p), DVec2::from_array(*expected));
            let got = case
                .intrinsics
                .project(p)
                .unwrap_or_else(|| panic!("{}: {p}", case.name));
            let err = (got - expected).length();
            assert!(
                err < TOLERANCE_PX,
                "{}: {p} -> {got}, OpenCV {expected}",
                case.name
            );
            worst = worst.max(err);
        }
    }
    println!(
        "max |ours - OpenCV {}| = {worst:.3e} px",
        fixture.opencv_version
    );
}

#[test]
fn unproject_then_project_returns_the_pixel() {
    let fixture = fixture();
    let mut worst = 0.0_f64;
    for case in &fixture.cases {
        let cam = &case.intrinsics;
        for (p, pixel) in case.points.iter().zip(&case.pixels) {
            let (p, pixel) = (DVec3::from_array(*p), DVec2::from_array(*pixel));
            let ray = cam
                .unproject(pixel)
                .unwrap_or_else(|| panic!("{}: {pixel}", case.name));
            assert!((ray.length() - 1.0).abs() < 1e-12, "{}: {ray}", case.name);
            assert!(
                (ray - p.normalize_or_zero()).length() < 1e-9,
                "{}: {ray} vs {p}",
                case.name
            );
            let back = cam
                .project(ray)
                .unwrap_or_else(|| panic!("{}: {ray}", case.name));
            let err = (back - pixel).length();
            assert!(
                err < TOLERANCE_PX,
                "{}: {pixel} -> {ray} -> {back}",
                case.name
            );
            worst = worst.max(err);
        }
    }
    println!("max unproject/project round-trip error = {worst:.3e} px");
}
