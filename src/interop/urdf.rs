//! URDF: one fixed joint per sensor from the vehicle link, and for cameras REP-103's pair of a
//! body link (x forward, y left, z up) and the optical link the images are stamped in.
//!
//! Export: `base_link → lidar` and `base_link → <camera>_link → <camera frame>` with the
//! optical joint `rpy="-π/2 0 -π/2"`. Import: every joint's origin composed from the vehicle
//! link down to each sensor's frame (any depth, any joint type at its zero position), so URDFs
//! written by other tools (a sensor-kit link in between, a mounting bracket) resolve too.

use std::collections::BTreeMap;
use std::path::Path;

use glam::{DQuat, DVec3};

use super::numbers::num;
use super::{ImportError, frames};
use crate::calib::{Rig, SensorKind};
use crate::geometry::Rigid;

fn origin(t: Rigid) -> String {
    let [r, p, y] = t.roll_pitch_yaw_rad();
    let v = t.translation;
    format!(
        "<origin xyz=\"{} {} {}\" rpy=\"{} {} {}\"/>",
        num(v.x),
        num(v.y),
        num(v.z),
        num(r),
        num(p),
        num(y)
    )
}

fn xml_escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

fn joint(out: &mut String, name: &str, parent: &str, child: &str, parent_from_child: Rigid) {
    out.push_str(&format!(
        "  <joint name=\"{}\" type=\"fixed\">\n    <parent link=\"{}\"/>\n    <child link=\"{}\"/>\n    {}\n  </joint>\n",
        xml_escape(name),
        xml_escape(parent),
        xml_escape(child),
        origin(parent_from_child)
    ));
}

/// A fixed joint of the exported URDF.
pub struct Joint {
    pub name: String,
    pub parent: String,
    pub child: String,
    pub parent_from_child: Rigid,
}

/// The links (vehicle frame first) and joints the URDF holds for `rig`: a LiDAR's frame under
/// the vehicle frame; a camera's body link under the vehicle frame and its optical frame
/// under the body link.
pub fn links_and_joints(rig: &Rig) -> (Vec<String>, Vec<Joint>) {
    let v = &rig.vehicle_frame;
    let mut links = vec![v.clone()];
    let mut joints = Vec::new();
    let mut add = |name: String, parent: &str, child: &str, parent_from_child: Rigid| {
        joints.push(Joint {
            name,
            parent: parent.to_owned(),
            child: child.to_owned(),
            parent_from_child,
        })
    };
    for s in &rig.sensors {
        if s.frame_id == *v {
            // The sensor defines the vehicle frame (PandaSet's pandar64): no joint to itself.
            continue;
        }
        match s.kind {
            SensorKind::Lidar => {
                add(
                    format!("{}_joint", s.name),
                    v,
                    &s.frame_id,
                    s.vehicle_from_sensor,
                );
                links.push(s.frame_id.clone());
            }
            SensorKind::Camera => {
                let body = frames::body_link(&s.frame_id);
                add(
                    format!("{}_joint", s.name),
                    v,
                    &body,
                    frames::vehicle_from_body(s),
                );
                add(
                    format!("{}_optical_joint", s.name),
                    &body,
                    &s.frame_id,
                    frames::body_from_optical(),
                );
                links.push(body);
                links.push(s.frame_id.clone());
            }
        }
    }
    (links, joints)
}

pub fn export(rig: &Rig) -> String {
    let (links, joint_list) = links_and_joints(rig);
    let mut joints = String::new();
    for j in &joint_list {
        joint(
            &mut joints,
            &j.name,
            &j.parent,
            &j.child,
            j.parent_from_child,
        );
    }
    let mut out = format!(
        "<?xml version=\"1.0\"?>\n\
         <!-- Written by rigcal {}. Every joint's origin is parent_from_child: a point in the child link\n     \
         maps into the parent link as p_parent = R(rpy) p_child + xyz (metres; radians; fixed-axis\n     \
         roll-pitch-yaw, R = Rz(yaw) Ry(pitch) Rx(roll)). Cameras (REP-103): <camera>_link is the body\n     \
         frame (x forward, y left, z up); the optical link (x right, y down, z forward) is the frame\n     \
         the images are stamped in. -->\n<robot name=\"rigcal_rig\">\n",
        env!("CARGO_PKG_VERSION")
    );
    for l in &links {
        out.push_str(&format!("  <link name=\"{}\"/>\n", xml_escape(l)));
    }
    out.push_str(&joints);
    out.push_str("</robot>\n");
    out
}

fn parse_triple(text: Option<&str>, what: &str) -> Result<DVec3, ImportError> {
    let Some(text) = text else {
        return Ok(DVec3::ZERO);
    };
    let v: Vec<f64> = text
        .split_whitespace()
        .map(|s| {
            s.parse::<f64>()
                .map_err(|_| format!("{what} '{text}': '{s}' is not a number"))
        })
        .collect::<Result<_, _>>()?;
    match v.as_slice() {
        [a, b, c] if v.iter().all(|x| x.is_finite()) => Ok(DVec3::new(*a, *b, *c)),
        _ => Err(format!("{what} '{text}' needs three finite numbers").into()),
    }
}

/// Every joint as `child → (parent, parent_from_child)`.
pub fn parse_joints(
    text: &str,
    path: &Path,
) -> Result<BTreeMap<String, (String, Rigid)>, ImportError> {
    let file = path.display();
    let doc =
        roxmltree::Document::parse(text).map_err(|e| format!("{file}: not valid XML: {e}"))?;
    let robot = doc.root_element();
    if robot.tag_name().name() != "robot" {
        return Err(format!(
            "{file}: not a URDF (the root element is <{}>, not <robot>)",
            robot.tag_name().name()
        )
        .into());
    }
    let mut edges = BTreeMap::new();
    for j in robot.children().filter(|n| n.has_tag_name("joint")) {
        let name = j.attribute("name").unwrap_or("?");
        let link = |tag: &str| {
            j.children()
                .find(|n| n.has_tag_name(tag))
                .and_then(|n| n.attribute("link"))
                .map(str::to_string)
                .ok_or_else(|| format!("{file}: joint '{name}' has no <{tag} link=…>"))
        };
        let (parent, child) = (link("parent")?, link("child")?);
        let o = j.children().find(|n| n.has_tag_name("origin"));
        let xyz = parse_triple(o.and_then(|o| o.attribute("xyz")), "xyz")
            .map_err(|e| format!("{file}: joint '{name}': {e}"))?;
        let rpy = parse_triple(o.and_then(|o| o.attribute("rpy")), "rpy")
            .map_err(|e| format!("{file}: joint '{name}': {e}"))?;
        let rotation = DQuat::from_euler(glam::EulerRot::ZYX, rpy.z, rpy.y, rpy.x);
        if edges
            .insert(child.clone(), (parent, Rigid::new(rotation, xyz)))
            .is_some()
        {
            return Err(format!("{file}: link '{child}' is the child of two joints").into());
        }
    }
    Ok(edges)
}

/// `ancestor_from_frame` by walking up the joints; `None` if `ancestor` is not above `frame`.
pub fn resolve(
    edges: &BTreeMap<String, (String, Rigid)>,
    ancestor: &str,
    frame: &str,
) -> Option<Rigid> {
    let mut t = Rigid::IDENTITY;
    let mut current = frame.to_string();
    for _ in 0..=edges.len() {
        if current == ancestor {
            return Some(t);
        }
        let (parent, parent_from_child) = edges.get(&current)?;
        t = *parent_from_child * t;
        current = parent.clone();
    }
    None // a cycle
}

#[cfg(test)]
mod tests {
    use super::super::test_rig;
    use super::*;

    #[test]
    fn joints_resolve_to_every_sensor() {
        let rig = test_rig::rig();
        let text = export(&rig);
        let edges = parse_joints(&text, Path::new("rig.urdf")).unwrap();
        for s in &rig.sensors {
            let t = resolve(&edges, "base_link", &s.frame_id).unwrap();
            let (r, d) = t.difference(s.vehicle_from_sensor);
            assert!(r < 1e-12 && d < 1e-12, "{}: {r} {d}", s.name);
        }
        // A camera's body link looks along the vehicle's yaw direction (x forward).
        let cam = rig.sensor("left_camera").unwrap();
        let body = resolve(&edges, "base_link", &frames::body_link(&cam.frame_id)).unwrap();
        let forward = body.transform_vector(DVec3::X);
        assert!((forward.y.atan2(forward.x) - 1.3).abs() < 0.05, "{forward}");
    }

    #[test]
    fn bad_urdf_is_named() {
        let p = Path::new("bad.urdf");
        assert!(
            parse_joints("<robot>", p)
                .unwrap_err()
                .to_string()
                .contains("bad.urdf")
        );
        assert!(
            parse_joints("<xacro/>", p)
                .unwrap_err()
                .to_string()
                .contains("<robot>")
        );
        let e = parse_joints(
            "<robot><joint name=\"j\"><parent link=\"a\"/><child link=\"b\"/><origin xyz=\"1 x 2\"/></joint></robot>",
            p,
        )
        .unwrap_err();
        assert!(
            e.to_string().contains("'j'") && e.to_string().contains("'x'"),
            "{e}"
        );
        let e = parse_joints(
            "<robot><joint name=\"j\"><child link=\"b\"/></joint></robot>",
            p,
        )
        .unwrap_err();
        assert!(e.to_string().contains("parent"), "{e}");
    }
}
