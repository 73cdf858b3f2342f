#![allow(clippy::unwrap_used, clippy::expect_used)]
//! Every MCAP written by real ROS 2 tools in ../shared/data/mcap-rosbag2 opens with the message
//! counts and topics of its INVENTORY.txt; schemas rigcal does not decode are listed, not fatal.

use std::path::PathBuf;

use rigcal::log::Drive;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data/mcap-rosbag2")
}

/// (relative path, message count, [(topic, schema)]) parsed from INVENTORY.txt.
fn inventory() -> Vec<(String, u64, Vec<(String, String)>)> {
    let text = std::fs::read_to_string(root().join("INVENTORY.txt")).unwrap();
    let mut out: Vec<(String, u64, Vec<(String, String)>)> = Vec::new();
    for line in text.lines() {
        let t = line.trim();
        if t.starts_with("('") {
            let parts: Vec<&str> = t
                .trim_matches(|c| c == '(' || c == ')')
                .split("', '")
                .collect();
            let topic = parts[0].trim_matches('\'').to_string();
            let schema = parts[1].trim_matches('\'').to_string();
            out.last_mut().unwrap().2.push((topic, schema));
        } else if let Some((path, rest)) = t.split_once(".mcap") {
            let msgs = rest
                .split_whitespace()
                .find_map(|w| w.strip_prefix("msgs="))
                .unwrap();
            out.push((format!("{path}.mcap"), msgs.parse().unwrap(), Vec::new()));
        }
    }
    out
}

#[test]
fn every_rosbag2_file_opens_with_inventory_counts() {
    let inv = inventory();
    assert!(inv.len() >= 15, "parsed {} files", inv.len());
    for (path, count, topics) in inv {
        let drive = Drive::open(&root().join(&path)).unwrap_or_else(|e| panic!("{path}: {e}"));
        let total: u64 = drive.topics.iter().map(|t| t.count).sum();
        assert_eq!(total, count, "{path}");
        for (topic, schema) in topics {
            let t = drive
                .topics
                .iter()
                .find(|t| t.topic == topic)
                .unwrap_or_else(|| panic!("{path}: {topic}"));
            assert_eq!(t.schema_name, schema, "{path}: {topic}");
            assert!(!t.understood, "{path}: {topic} is not sensor data");
        }
        assert!(drive.streams.is_empty());
    }
}
