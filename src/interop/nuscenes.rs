//! nuScenes `calibrated_sensor.json`: a list of records, each the sensor's pose in the ego
//! (vehicle) frame — `ego_from_sensor`, translation in metres and rotation as a quaternion in
//! nuScenes' `[w, x, y, z]` order — and, for cameras, the 3×3 intrinsic matrix (LiDARs: `[]`).
//! Camera frames are optical, as in nuScenes. Tokens are derived from the sensor names, so an
//! export is reproducible. `channel`, `modality` and `transform` are rigcal's additions (JSON
//! has no comments: `transform` spells out the direction), and so are `camera_distortion_model`
//! and `camera_distortion` for a camera with a lens model: nuScenes' images are undistorted
//! and its records hold K only, which alone would describe a pinhole.

use serde_json::json;

use crate::calib::{Rig, SensorKind};

/// A 32-hex-digit token from a name (two FNV-1a 64 hashes with different offsets).
pub fn token(kind: &str, name: &str) -> String {
    let fnv = |offset: u64| {
        let mut h = offset;
        for b in kind.bytes().chain([0u8]).chain(name.bytes()) {
            h ^= b as u64;
            h = h.wrapping_mul(0x0100_0000_01b3);
        }
        h
    };
    format!(
        "{:016x}{:016x}",
        fnv(0xcbf2_9ce4_8422_2325),
        fnv(0x6c62_272e_07bb_0142)
    )
}

pub fn export(rig: &Rig) -> String {
    let records: Vec<serde_json::Value> = rig
        .sensors
        .iter()
        .map(|s| {
            let t = s.vehicle_from_sensor;
            let q = t.rotation;
            let intrinsic = match (&s.kind, &s.camera) {
                (SensorKind::Camera, Some(c)) => {
                    json!([[c.fx, 0.0, c.cx], [0.0, c.fy, c.cy], [0.0, 0.0, 1.0]])
                }
                _ => json!([]),
            };
            let mut record = json!({
                "token": token("calibrated_sensor", &s.name),
                "sensor_token": token("sensor", &s.name),
                "channel": s.name,
                "modality": s.kind.as_str(),
                "translation": t.translation.to_array(),
                "rotation": [q.w, q.x, q.y, q.z],
                "camera_intrinsic": intrinsic,
                "transform": "ego_from_sensor: p_ego = R(rotation) p_sensor + translation; metres; rotation is w, x, y, z; camera frames are optical (x right, y down, z forward)",
            });
            // nuScenes images are undistorted and its records carry K only: a camera with a
            // lens model says so, so its K is not taken for a pinhole's.
            if let Some(c) = s.camera.as_ref().filter(|c| c.has_lens_distortion()) {
                record["camera_distortion_model"] = json!(c.model.as_str());
                record["camera_distortion"] = json!(c.distortion);
            }
            record
        })
        .collect();
    // Plain data with string keys serialises.
    let mut text = serde_json::to_string_pretty(&records).unwrap_or_default();
    text.push('\n');
    text
}

#[cfg(test)]
mod tests {
    use super::super::test_rig;
    use super::*;
    use crate::geometry::Rigid;

    #[test]
    fn records_are_ego_from_sensor_with_wxyz() {
        let rig = test_rig::rig();
        let v: serde_json::Value = serde_json::from_str(&export(&rig)).unwrap();
        let records = v.as_array().unwrap();
        assert_eq!(records.len(), rig.sensors.len());
        for (r, s) in records.iter().zip(&rig.sensors) {
            let f = |k: &str| -> Vec<f64> {
                r[k].as_array()
                    .unwrap()
                    .iter()
                    .map(|x| x.as_f64().unwrap())
                    .collect()
            };
            let (t, q) = (f("translation"), f("rotation"));
            let got = Rigid::new(
                glam::DQuat::from_xyzw(q[1], q[2], q[3], q[0]),
                glam::DVec3::new(t[0], t[1], t[2]),
            );
            let (dr, dt) = got.difference(s.vehicle_from_sensor);
            assert!(dr < 1e-12 && dt == 0.0);
            assert_eq!(r["token"].as_str().unwrap().len(), 32);
            let k = r["camera_intrinsic"].as_array().unwrap();
            assert_eq!(k.len(), if s.kind == SensorKind::Camera { 3 } else { 0 });
        }
        assert_ne!(token("sensor", "a"), token("calibrated_sensor", "a"));
        // A camera with a lens model says so beside its K; a pinhole does not.
        for (r, s) in records.iter().zip(&rig.sensors) {
            let lens = s.camera.as_ref().is_some_and(|c| c.has_lens_distortion());
            assert_eq!(
                r.get("camera_distortion_model").is_some(),
                lens,
                "{}",
                s.name
            );
            if let Some(c) = s.camera.as_ref().filter(|_| lens) {
                assert_eq!(
                    r["camera_distortion"].as_array().unwrap().len(),
                    c.distortion.len()
                );
            }
        }
    }
}
