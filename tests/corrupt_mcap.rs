#![allow(clippy::unwrap_used, clippy::expect_used)]
//! Truncated and bit-flipped MCAP files never panic: they open with problems listed, or fail with
//! an error naming the file. A property test over many random corruptions of real files.

use std::path::{Path, PathBuf};

use proptest::prelude::*;
use rigcal::log::Drive;
use tempfile::TempDir;

fn fixture(name: &str) -> Vec<u8> {
    std::fs::read(
        PathBuf::from(env!("CARGO_MANIFEST_DIR"))
            .join("tests/fixtures/mcap")
            .join(name),
    )
    .unwrap()
}

/// A scratch folder, removed when dropped.
fn scratch() -> TempDir {
    tempfile::Builder::new()
        .prefix("rigcal-corrupt-")
        .tempdir()
        .unwrap()
}

fn write_tmp(dir: &TempDir, bytes: &[u8], tag: &str) -> PathBuf {
    let path = dir.path().join(format!("{tag}.mcap"));
    std::fs::write(&path, bytes).unwrap();
    path
}

/// Open and touch every sweep and image; any error must name the file.
fn exercise(path: &Path) {
    match Drive::open(path) {
        Ok(drive) => {
            for s in &drive.streams {
                for i in 0..s.frames.len() {
                    let r = match s.kind {
                        rigcal::calib::SensorKind::Lidar => {
                            drive.load_sweep(&s.sensor, i).map(|_| ())
                        }
                        rigcal::calib::SensorKind::Camera => {
                            drive.load_image(&s.sensor, i).map(|_| ())
                        }
                    };
                    if let Err(e) = r {
                        assert!(e.to_string().contains(&path.display().to_string()), "{e}");
                    }
                }
            }
            let _ = rigcal::cli::inspect::report(&drive);
        }
        Err(e) => assert!(e.to_string().contains(&path.display().to_string()), "{e}"),
    }
}

#[test]
fn truncated_at_every_kind_of_boundary() {
    let dir = scratch();
    for name in ["ros2.mcap", "foxglove_protobuf.mcap", "foxglove_json.mcap"] {
        let bytes = fixture(name);
        for cut in [
            0,
            4,
            8,
            9,
            20,
            100,
            bytes.len() / 3,
            bytes.len() / 2,
            bytes.len() - 30,
            bytes.len() - 1,
        ] {
            exercise(&write_tmp(&dir, &bytes[..cut], &format!("trunc-{cut}")));
        }
    }
}

#[test]
fn a_truncated_log_keeps_what_came_before() {
    let bytes = fixture("ros2.mcap");
    let dir = scratch();
    let path = write_tmp(&dir, &bytes[..bytes.len() * 2 / 3], "two-thirds");
    let drive = Drive::open(&path).unwrap();
    assert!(!drive.problems.is_empty(), "truncation is reported");
    let total: u64 = drive.topics.iter().map(|t| t.count).sum();
    assert!(total > 10, "messages before the damage are kept ({total})");
}

/// A log cut inside its first chunk has nothing to give: the error says so with every reason,
/// why the summary was not used and where the file ends.
#[test]
fn a_log_cut_in_its_first_chunk_says_why_it_is_unusable() {
    let bytes = fixture("ros2.mcap");
    let dir = scratch();
    let offset = first_chunk(&bytes);
    let path = write_tmp(&dir, &bytes[..offset + 40], "cut-in-chunk");
    let err = Drive::open(&path).unwrap_err().to_string();
    assert!(err.contains("cut-in-chunk.mcap"), "{err}");
    assert!(err.contains("no channels or messages found"), "{err}");
    assert!(err.contains("summary section is unusable"), "{err}");
    assert!(err.contains("the file ends first (truncated)"), "{err}");
}

/// Messages per topic, as the drive lists them.
fn message_count(drive: &Drive) -> u64 {
    drive.topics.iter().map(|t| t.count).sum()
}

/// The offset of the first chunk record (opcode 0x06) of an intact file.
fn first_chunk(bytes: &[u8]) -> usize {
    let mut offset = 8usize;
    while bytes[offset] != 0x06 {
        let len = u64::from_le_bytes(bytes[offset + 1..offset + 9].try_into().unwrap()) as usize;
        offset += 9 + len;
    }
    offset
}

/// A damaged closing magic with an intact footer before it: the summary is still read, and
/// every message with it.
#[test]
fn a_damaged_closing_magic_still_reads_the_summary() {
    let bytes = fixture("ros2.mcap");
    let dir = scratch();
    let intact = Drive::open(&write_tmp(&dir, &bytes, "intact")).unwrap();
    let mut damaged = bytes.clone();
    let last = damaged.len() - 1;
    damaged[last] ^= 0xFF;
    let drive = Drive::open(&write_tmp(&dir, &damaged, "end-magic")).unwrap();
    assert_eq!(message_count(&drive), message_count(&intact));
    assert!(
        drive
            .problems
            .iter()
            .any(|p| p.what.contains("closing magic bytes are damaged")),
        "{:?}",
        drive.problems
    );
}

/// A chunk whose record length is damaged, in a log whose summary is unusable too: the walk from
/// the start skips to the next chunk and keeps every later message.
#[test]
fn a_damaged_record_length_loses_only_its_own_chunk() {
    let bytes = fixture("ros2.mcap");
    let dir = scratch();
    let intact = Drive::open(&write_tmp(&dir, &bytes, "intact")).unwrap();
    let mut damaged = bytes.clone();
    let chunk = first_chunk(&damaged);
    damaged[chunk + 1..chunk + 9].copy_from_slice(&(u64::MAX / 4).to_le_bytes());
    // The footer's opcode and the closing magic: no summary to fall back on.
    let footer = damaged.len() - 8 - 29;
    damaged[footer] = 0xFF;
    let last = damaged.len() - 1;
    damaged[last] ^= 0xFF;
    let path = write_tmp(&dir, &damaged, "bad-length");
    let drive = Drive::open(&path).unwrap();
    let (kept, all) = (message_count(&drive), message_count(&intact));
    assert!(kept > 0 && kept < all, "{kept} of {all} messages");
    // The later chunks decode: their schemas, defined in the damaged chunk, come from the
    // summary section the walk reads past the data end.
    let frames = |d: &Drive| -> usize { d.streams.iter().map(|s| s.frames.len()).sum() };
    assert!(
        frames(&drive) > 0,
        "{} of {} sensor frames",
        frames(&drive),
        frames(&intact)
    );
    assert!(
        drive
            .problems
            .iter()
            .any(|p| p.what.contains(&format!("at byte {chunk} claims"))
                && p.what.contains("to the next chunk at byte")),
        "{:?}",
        drive.problems
    );
    exercise(&path);
}

#[test]
fn not_mcap_is_a_clear_error() {
    let dir = scratch();
    let path = write_tmp(&dir, b"hello, world", "text");
    let err = Drive::open(&path).unwrap_err().to_string();
    assert!(
        err.contains("not an MCAP file") && err.contains("text.mcap"),
        "{err}"
    );
    let err = Drive::open(Path::new("/nonexistent/x.mcap"))
        .unwrap_err()
        .to_string();
    assert!(err.contains("/nonexistent/x.mcap"), "{err}");
    // An empty file, a directory and a rosbag2-like folder say what they are.
    let empty = write_tmp(&dir, b"", "empty");
    let err = Drive::open(&empty).unwrap_err().to_string();
    assert!(err.contains("the file is empty"), "{err}");
    let err = Drive::open(dir.path()).unwrap_err().to_string();
    assert!(
        err.contains("directory") && err.contains("empty.mcap"),
        "{err}"
    );
    let bare = dir.path().join("bare");
    std::fs::create_dir(&bare).unwrap();
    let err = Drive::open(&bare).unwrap_err().to_string();
    assert!(err.contains("it is a directory, not a file"), "{err}");
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 96, ..ProptestConfig::default() })]

    #[test]
    fn bit_flips_never_panic(file in 0usize..3, flips in proptest::collection::vec((any::<prop::sample::Index>(), 0u8..8), 1..8)) {
        let name = ["ros2.mcap", "foxglove_protobuf.mcap", "foxglove_json.mcap"][file];
        let mut bytes = fixture(name);
        for (idx, bit) in &flips {
            let i = idx.index(bytes.len());
            bytes[i] ^= 1 << bit;
        }
        let dir = scratch();
        exercise(&write_tmp(&dir, &bytes, "flip"));
    }
}

/// A log whose messages sit outside chunks and whose summary has channels but no statistics
/// (both allowed by the MCAP spec) reads every message, as the same log written chunked does.
#[test]
fn unchunked_messages_with_a_summary_without_statistics_are_read() {
    let bytes = fixture("ros2.mcap");
    let dir = scratch();
    let path = dir.path().join("unchunked.mcap");
    {
        let file = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
        let mut writer = mcap::WriteOptions::new()
            .use_chunks(false)
            .emit_statistics(false)
            .profile("ros2")
            .create(file)
            .unwrap();
        for message in mcap::MessageStream::new(&bytes).unwrap() {
            writer.write(&message.unwrap()).unwrap();
        }
        writer.finish().unwrap();
    }
    let original = Drive::open(&write_tmp(&dir, &bytes, "chunked")).unwrap();
    let rewritten = Drive::open(&path).unwrap();
    let counts = |d: &Drive| -> Vec<(String, usize)> {
        d.streams
            .iter()
            .map(|s| (s.topic.clone(), s.frames.len()))
            .collect()
    };
    assert!(!counts(&original).is_empty());
    assert_eq!(counts(&rewritten), counts(&original));
}
