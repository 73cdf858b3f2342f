//! A damaged copy of a drive, for showing that bad frames never sink a run: every fifth point
//! cloud of each topic (from the first) cut to half its bytes and every fifth JPEG's
//! start-of-image marker zeroed; the container itself stays intact, so the damage is only in
//! the payloads a run decodes (`tests/damaged_drive.rs`, `examples/damage_drive.rs`).

use std::collections::HashMap;
use std::path::Path;

use super::writer::WriterError;

/// Write `from` into `to` damaged as above; returns how many messages it damaged.
pub fn damaged_copy(from: &Path, to: &Path) -> Result<usize, WriterError> {
    let io = |path: &Path, what: &str| {
        let (path, what) = (path.to_path_buf(), what.to_owned());
        move |source| WriterError::Io { path, what, source }
    };
    let mcap = |path: &Path| {
        let path = path.to_path_buf();
        move |source| WriterError::Mcap { path, source }
    };
    let bytes = std::fs::read(from).map_err(io(from, "cannot read"))?;
    let file = std::fs::File::create(to).map_err(io(to, "cannot create"))?;
    let mut writer = mcap::WriteOptions::new()
        .profile("ros2")
        .create(std::io::BufWriter::new(file))
        .map_err(mcap(to))?;
    let mut seen = HashMap::<String, usize>::new();
    let mut damaged = 0;
    let unreadable = |source: mcap::McapError| WriterError::Invalid {
        path: from.to_path_buf(),
        what: format!("not a readable MCAP: {source}"),
    };
    let stream = mcap::MessageStream::new(&bytes).map_err(unreadable)?;
    for message in stream {
        let mut message = message.map_err(unreadable)?;
        let schema = message
            .channel
            .schema
            .as_ref()
            .map(|s| s.name.clone())
            .unwrap_or_default();
        // The first of each topic, then every fifth.
        let n = seen.entry(message.channel.topic.clone()).or_default();
        *n += 1;
        if *n % 5 == 1 {
            let mut data = message.data.into_owned();
            if schema == "sensor_msgs/msg/PointCloud2" {
                data.truncate(data.len() / 2);
                damaged += 1;
            } else if schema == "sensor_msgs/msg/CompressedImage"
                && let Some(at) = data.windows(3).position(|w| w == [0xFF, 0xD8, 0xFF])
            {
                data[at..at + 3].fill(0);
                damaged += 1;
            }
            message.data = data.into();
        }
        writer.write(&message).map_err(mcap(to))?;
    }
    writer.finish().map_err(mcap(to))?;
    Ok(damaged)
}
