//! ROS 2 static transforms: `static_transform_publisher` commands and an XML launch file.
//!
//! One publisher per sensor, parent = the vehicle frame, child = the sensor's frame (the optical
//! frame for cameras, the frame the data are stamped in). tf2's convention: the transform is
//! the child's pose in the parent, `p_parent = R(q) · p_child + (x, y, z)`, i.e.
//! `vehicle_from_sensor`. The flag form (`--x … --frame-id … --child-frame-id …`, ROS 2 Humble
//! and later) with a quaternion avoids the legacy positional form's yaw-pitch-roll order.

use super::numbers::num;
use super::text::comment;
use crate::calib::{Rig, Sensor};

/// `word` as one POSIX shell word: unchanged when it is plainly safe, else single-quoted (also
/// how ROS 2 launch splits `args`, with shlex).
pub fn shell_word(word: &str) -> String {
    let safe = |c: char| c.is_ascii_alphanumeric() || "_-./:@%+=,".contains(c);
    if !word.is_empty() && word.chars().all(safe) {
        word.to_string()
    } else {
        format!("'{}'", word.replace('\'', "'\\''"))
    }
}

/// Text safe inside an XML comment: no control characters and no `--`.
fn xml_comment(text: &str) -> String {
    let mut t = comment(text).replace('&', "&amp;").replace('<', "&lt;");
    while t.contains("--") {
        t = t.replace("--", "- -");
    }
    if t.ends_with('-') {
        t.push(' ');
    }
    t
}

fn args(rig: &Rig, s: &Sensor) -> String {
    let t = s.vehicle_from_sensor;
    let q = t.rotation;
    format!(
        "--x {} --y {} --z {} --qx {} --qy {} --qz {} --qw {} --frame-id {} --child-frame-id {}",
        num(t.translation.x),
        num(t.translation.y),
        num(t.translation.z),
        num(q.x),
        num(q.y),
        num(q.z),
        num(q.w),
        shell_word(&rig.vehicle_frame),
        shell_word(&s.frame_id)
    )
}

const DIRECTION: &str = "Each publishes parent_from_child, the child frame's pose in the parent: p_parent = R(q) p_child + (x, y, z); metres; quaternion x y z w (Hamilton). the frame-id flag names the parent (the vehicle frame), child-frame-id the sensor's frame (cameras: the OpenCV optical frame, x right, y down, z forward).";

/// A POSIX shell script starting one publisher per sensor.
pub fn script(rig: &Rig) -> String {
    let mut out = format!(
        "#!/bin/sh\n# Static transforms of the rig, written by rigcal {}.\n# {}\n# Run in a sourced ROS 2 environment; Ctrl-C stops them all.\nset -e\ntrap 'kill 0' INT TERM\n",
        env!("CARGO_PKG_VERSION"),
        DIRECTION
    );
    for s in &rig.sensors {
        if s.frame_id == rig.vehicle_frame {
            out.push_str(&format!(
                "# {}: its frame is the vehicle frame (identity): nothing to publish\n",
                comment(&s.name)
            ));
            continue;
        }
        out.push_str(&format!(
            "# {} ({}): vehicle_from_sensor\nros2 run tf2_ros static_transform_publisher {} &\n",
            comment(&s.name),
            s.kind.as_str(),
            args(rig, s)
        ));
    }
    out.push_str("wait\n");
    out
}

/// A node name ROS accepts: letters, digits and `_`, not starting with a digit.
fn node_name(sensor: &str) -> String {
    let mut n: String = sensor
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect();
    if n.starts_with(|c: char| c.is_ascii_digit()) {
        n.insert(0, '_');
    }
    format!("rigcal_{n}_tf")
}

/// A ROS 2 XML launch file (`ros2 launch static_tf.launch.xml`).
pub fn launch(rig: &Rig) -> String {
    let esc = |s: &str| {
        s.replace('&', "&amp;")
            .replace('"', "&quot;")
            .replace('<', "&lt;")
    };
    let mut out = format!(
        "<?xml version=\"1.0\"?>\n<!-- Static transforms of the rig, written by rigcal {}.\n     {} -->\n<launch>\n",
        env!("CARGO_PKG_VERSION"),
        DIRECTION
    );
    let mut names: Vec<String> = Vec::new();
    for s in rig
        .sensors
        .iter()
        .filter(|s| s.frame_id != rig.vehicle_frame)
    {
        // Distinct sensor names can map to one node name ("a-b", "a_b"): number the repeats.
        let base = node_name(&s.name);
        let mut name = base.clone();
        let mut n = 2;
        while names.contains(&name) {
            name = format!("{base}{n}");
            n += 1;
        }
        names.push(name.clone());
        out.push_str(&format!(
            "  <!-- {}: vehicle_from_sensor -->\n  <node pkg=\"tf2_ros\" exec=\"static_transform_publisher\" name=\"{}\" args=\"{}\"/>\n",
            xml_comment(&s.name),
            name,
            esc(&args(rig, s))
        ));
    }
    out.push_str("</launch>\n");
    out
}

/// `(parent, child, translation, quaternion xyzw)` read back from the flag form, for tests.
pub fn parse_args(line: &str) -> Option<(String, String, [f64; 3], [f64; 4])> {
    let words = shell_words(line)?;
    let get = |flag: &str| {
        words
            .iter()
            .position(|w| *w == flag)
            .and_then(|i| words.get(i + 1))
            .cloned()
    };
    let f = |flag: &str| get(flag).and_then(|v| v.parse::<f64>().ok());
    Some((
        get("--frame-id")?.to_string(),
        get("--child-frame-id")?.to_string(),
        [f("--x")?, f("--y")?, f("--z")?],
        [f("--qx")?, f("--qy")?, f("--qz")?, f("--qw")?],
    ))
}

/// Split a line into shell words (plain words and single-quoted ones), as written by
/// [`shell_word`]; `None` on an unterminated quote.
pub fn shell_words(line: &str) -> Option<Vec<String>> {
    let mut words = Vec::new();
    let mut word: Option<String> = None;
    let mut chars = line.chars();
    while let Some(c) = chars.next() {
        match c {
            '\'' => {
                let w = word.get_or_insert_with(String::new);
                loop {
                    match chars.next()? {
                        '\'' => break,
                        q => w.push(q),
                    }
                }
            }
            '\\' => word.get_or_insert_with(String::new).push(chars.next()?),
            c if c.is_whitespace() => words.extend(word.take()),
            c => word.get_or_insert_with(String::new).push(c),
        }
    }
    words.extend(word);
    Some(words)
}

#[cfg(test)]
mod tests {
    use super::super::test_rig;
    use super::*;
    use crate::geometry::Rigid;

    fn check(lines: Vec<(String, String, [f64; 3], [f64; 4])>, rig: &Rig) {
        assert_eq!(lines.len(), rig.sensors.len());
        for ((parent, child, t, q), s) in lines.into_iter().zip(&rig.sensors) {
            assert_eq!(
                (parent.as_str(), child.as_str()),
                ("base_link", s.frame_id.as_str())
            );
            let got = Rigid::new(glam::DQuat::from_array(q), glam::DVec3::from_array(t));
            let (r, d) = got.difference(s.vehicle_from_sensor);
            assert!(r < 1e-12 && d < 1e-12);
        }
    }

    #[test]
    fn script_and_launch_carry_vehicle_from_sensor() {
        let rig = test_rig::rig();
        let sh = script(&rig);
        assert!(sh.starts_with("#!/bin/sh") && sh.contains("p_parent = R(q) p_child"));
        check(
            sh.lines()
                .filter(|l| l.starts_with("ros2 run"))
                .filter_map(parse_args)
                .collect(),
            &rig,
        );
        let xml = launch(&rig);
        let doc = roxmltree::Document::parse(&xml).unwrap();
        let nodes: Vec<_> = doc
            .descendants()
            .filter(|n| n.has_tag_name("node"))
            .collect();
        assert!(
            nodes
                .iter()
                .all(|n| n.attribute("exec") == Some("static_transform_publisher"))
        );
        check(
            nodes
                .iter()
                .filter_map(|n| n.attribute("args").and_then(parse_args))
                .collect(),
            &rig,
        );
        assert_eq!(node_name("cam/0"), "rigcal_cam_0_tf");
        for w in ["base_link", "it's here", "a b", "$(rm -rf ~)", ""] {
            assert_eq!(
                shell_words(&shell_word(w)).unwrap(),
                vec![w.to_string()],
                "{w}"
            );
        }
        assert_eq!(node_name("0cam"), "rigcal__0cam_tf");
    }

    #[test]
    fn hostile_names_stay_names() {
        let mut rig = test_rig::rig();
        rig.sensors[0].name = "evil\nrm -rf ~ --".into();
        rig.sensors[0].frame_id = "it's; $(reboot)".into();
        rig.sensors[1].name = "lidar-front".into();
        rig.sensors[2].name = "lidar_front".into();
        let sh = script(&rig);
        // Every line is a comment, a publisher, or the script's own framing.
        for line in sh.lines() {
            assert!(
                line.starts_with('#')
                    || line.starts_with("ros2 run")
                    || ["set -e", "trap 'kill 0' INT TERM", "wait"].contains(&line),
                "{line}"
            );
        }
        check(
            sh.lines()
                .filter(|l| l.starts_with("ros2 run"))
                .filter_map(parse_args)
                .collect(),
            &rig,
        );
        let xml = launch(&rig);
        let doc = roxmltree::Document::parse(&xml).unwrap();
        let names: Vec<&str> = doc
            .descendants()
            .filter(|n| n.has_tag_name("node"))
            .filter_map(|n| n.attribute("name"))
            .collect();
        let mut unique = names.clone();
        unique.sort();
        unique.dedup();
        assert_eq!(unique.len(), names.len(), "{names:?}");
        let args: Vec<_> = doc
            .descendants()
            .filter(|n| n.has_tag_name("node"))
            .filter_map(|n| n.attribute("args").and_then(parse_args))
            .collect();
        check(args, &rig);
    }
}
