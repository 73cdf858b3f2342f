//! The rig as a ROS 2 MCAP: one `tf2_msgs/TFMessage` on `/tf_static` (parent = the vehicle
//! frame, child = each sensor's frame, transform = the child's pose in the parent, i.e.
//! `vehicle_from_sensor`) and a `sensor_msgs/CameraInfo` per camera on its camera-info topic,
//! written by the same writer as the simulator's drives (message definitions embedded, so
//! Foxglove, Rerun and `ros2 bag` decode it). Import reads `/tf_static` and CameraInfo from any
//! MCAP through the log reader and resolves each sensor's frame from the vehicle frame.

use std::path::Path;

use super::ImportError;
use crate::calib::{Rig, SensorKind};
use crate::log::Drive;
use crate::log::tf::normalize_frame;
use crate::sim::writer::{Ros2McapWriter, WriterError};

/// The camera-info topic of a camera: the one it lists, or `/<name>/camera_info`.
pub fn camera_info_topic(s: &crate::calib::Sensor) -> String {
    s.topics
        .iter()
        .find(|t| t.ends_with("camera_info"))
        .cloned()
        .unwrap_or_else(|| format!("/{}/camera_info", s.name))
}

/// The MCAP's bytes (written in memory).
pub fn export(rig: &Rig) -> Result<Vec<u8>, WriterError> {
    let mut w = Ros2McapWriter::in_memory()?;
    fill(rig, &mut w)?;
    w.finish_bytes()
}

/// Write the MCAP to `path` (atomically).
pub fn write(rig: &Rig, path: &Path) -> Result<(), WriterError> {
    let mut w = Ros2McapWriter::create(path)?;
    fill(rig, &mut w)?;
    w.finish()
}

/// The rig's /tf_static and every camera's CameraInfo, stamped 0.
fn fill(rig: &Rig, w: &mut Ros2McapWriter) -> Result<(), WriterError> {
    let transforms: Vec<_> = rig
        .sensors
        .iter()
        // tf2 ignores a transform from a frame to itself (a sensor that is the vehicle frame).
        .filter(|s| s.frame_id != rig.vehicle_frame)
        .map(|s| {
            (
                rig.vehicle_frame.clone(),
                s.frame_id.clone(),
                s.vehicle_from_sensor,
            )
        })
        .collect();
    w.write_tf_static(0, &transforms)?;
    for s in rig.cameras() {
        if let Some(c) = &s.camera {
            w.write_camera_info(&camera_info_topic(s), 0, &s.frame_id, c)?;
        }
    }
    Ok(())
}

/// `base`'s sensors with the extrinsics (and camera intrinsics) the MCAP at `path` gives their
/// frames; returns the names of the sensors it matched.
pub fn import(path: &Path, base: &Rig) -> Result<(Rig, Vec<String>), ImportError> {
    let drive = Drive::open(path)?;
    if drive.tf.static_edges.is_empty() {
        return Err(ImportError::Invalid(format!(
            "{}: has no /tf_static transforms",
            path.display()
        )));
    }
    let mut rig = base.clone();
    let mut matched = Vec::new();
    for s in &mut rig.sensors {
        let frame = normalize_frame(&s.frame_id);
        let Some(t) = drive
            .tf
            .static_transform(&normalize_frame(&base.vehicle_frame), &frame)
        else {
            continue;
        };
        s.vehicle_from_sensor = t;
        if s.kind == SensorKind::Camera
            && let Some(c) = drive.camera_infos.get(&frame)
        {
            s.camera = Some(c.clone());
        }
        matched.push(s.name.clone());
    }
    Ok((rig, matched))
}

#[cfg(test)]
mod tests {
    use super::super::test_rig;
    use super::*;

    #[test]
    fn round_trip_through_the_log_reader() {
        let rig = test_rig::rig();
        let bytes = export(&rig).unwrap();
        let dir = std::env::temp_dir().join(format!("rigcal-mcap-tf-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("rig.mcap");
        std::fs::write(&path, &bytes).unwrap();
        // Written to a file: the same bytes as in memory, and no temporary file left beside.
        let written = dir.join("written.mcap");
        write(&rig, &written).unwrap();
        assert_eq!(std::fs::read(&written).unwrap(), bytes);
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 2);
        let mut blank = rig.clone();
        for s in &mut blank.sensors {
            s.vehicle_from_sensor = crate::geometry::Rigid::IDENTITY;
            if let Some(c) = &mut s.camera {
                c.fx = 1.0;
            }
        }
        let (back, matched) = import(&path, &blank).unwrap();
        assert_eq!(matched.len(), rig.sensors.len());
        let (r, t) = test_rig::max_difference(&rig, &back);
        assert!(r < 1e-12 && t < 1e-12, "{r} {t}");
        for (a, b) in rig.cameras().zip(back.cameras()) {
            let (ca, cb) = (a.camera.as_ref().unwrap(), b.camera.as_ref().unwrap());
            assert_eq!(
                (ca.fx, ca.cx, ca.model),
                (cb.fx, cb.cx, cb.model),
                "{}",
                a.name
            );
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
