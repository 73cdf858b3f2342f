//! Small helpers shared by every module: atomic file writes, a fast hasher for integer keys,
//! handing freed memory back to the system.

use std::io::Write;
use std::path::Path;

/// Where a write to `path` lands.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum OutputTarget {
    /// A regular file, or none yet: written beside it and renamed over it. A symbolic link is
    /// followed, so the file it points to is replaced and the link stays a link.
    Replace(std::path::PathBuf),
    /// Something a rename must not replace (a device such as `/dev/null` or `/dev/stdout`, a
    /// pipe): written to directly.
    Direct(std::path::PathBuf),
}

/// Resolve an output path: follow symbolic links (also one whose target does not exist yet)
/// and tell a regular file from a device or pipe. A directory is an error.
pub fn output_target(path: &Path) -> std::io::Result<OutputTarget> {
    // What the path names after every link (the kernel's own resolution: /dev/stdout is a link
    // to /proc/self/fd/1, which names a pipe or terminal only the kernel can follow).
    match std::fs::metadata(path) {
        Ok(m) if m.is_dir() => {
            return Err(std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                format!("{} is a directory", path.display()),
            ));
        }
        Ok(m) if !m.is_file() => return Ok(OutputTarget::Direct(path.to_path_buf())),
        // /dev/stdout redirected to a file resolves through /proc/self/fd to that file;
        // replacing it by a rename would leave the shell's descriptor on the unlinked old one.
        Ok(_) if path.starts_with("/dev") || path.starts_with("/proc") => {
            return Ok(OutputTarget::Direct(path.to_path_buf()));
        }
        _ => {}
    }
    // A regular file or none yet: the file the links end at is the one to replace.
    let mut p = path.to_path_buf();
    // As many links as Linux follows before ELOOP, and the file they end at.
    for _ in 0..=40 {
        match std::fs::symlink_metadata(&p) {
            Ok(m) if m.file_type().is_symlink() => {
                let target = std::fs::read_link(&p)?;
                p = match p.parent() {
                    Some(dir) if target.is_relative() => dir.join(target),
                    _ => target,
                };
            }
            Ok(m) if m.is_dir() => {
                return Err(std::io::Error::new(
                    std::io::ErrorKind::InvalidInput,
                    format!("{} is a directory", p.display()),
                ));
            }
            Ok(m) if !m.is_file() => return Ok(OutputTarget::Direct(p)),
            _ => return Ok(OutputTarget::Replace(p)),
        }
    }
    Err(std::io::Error::new(
        std::io::ErrorKind::InvalidInput,
        format!("{}: too many levels of symbolic links", path.display()),
    ))
}

/// The directory a file at `path` lives in (`.` for a bare file name).
fn parent_dir(path: &Path) -> &Path {
    match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    }
}

/// Whether a file can be written at `path`, checked before long work rather than after it: not
/// a directory, and its directory exists (after links).
pub fn check_output(path: &Path) -> std::io::Result<()> {
    let OutputTarget::Replace(p) = output_target(path)? else {
        return Ok(());
    };
    let dir = parent_dir(&p);
    if !dir.is_dir() {
        return Err(std::io::Error::new(
            std::io::ErrorKind::NotFound,
            format!("the directory {} does not exist", dir.display()),
        ));
    }
    Ok(())
}

/// Whether two paths name the same existing file (after links), so an output would overwrite
/// an input.
pub fn same_file(a: &Path, b: &Path) -> bool {
    match (std::fs::canonicalize(a), std::fs::canonicalize(b)) {
        (Ok(a), Ok(b)) => a == b,
        // A file not written yet: compare where the two would be written.
        _ => match (landing_place(a), landing_place(b)) {
            (Some(a), Some(b)) => a == b,
            _ => false,
        },
    }
}

/// Where a write to `path` would create its file: its directory canonicalised, and its name
/// (after links).
fn landing_place(path: &Path) -> Option<std::path::PathBuf> {
    let OutputTarget::Replace(p) = output_target(path).ok()? else {
        return Some(path.to_path_buf());
    };
    Some(
        std::fs::canonicalize(parent_dir(&p))
            .ok()?
            .join(p.file_name()?),
    )
}

/// Write `bytes` to `path` atomically: a temporary file in the same directory, fsync, rename.
/// A crash leaves either the old file or the new one, never half of one. A symbolic link is
/// followed (its target is replaced); a device or pipe is written to directly
/// ([`output_target`]).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let path = match output_target(path)? {
        OutputTarget::Direct(p) => {
            let mut f = std::fs::OpenOptions::new().write(true).open(p)?;
            return f.write_all(bytes).and_then(|()| f.flush());
        }
        OutputTarget::Replace(p) => p,
    };
    let path = path.as_path();
    let dir = parent_dir(path);
    let file_name = path.file_name().ok_or_else(|| {
        std::io::Error::new(std::io::ErrorKind::InvalidInput, "path has no file name")
    })?;
    let mut tmp_name = std::ffi::OsString::from(".");
    tmp_name.push(file_name);
    tmp_name.push(format!(".tmp{}", std::process::id()));
    let tmp = dir.join(tmp_name);
    let result = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        // A replaced file keeps its permissions (an executable script stays executable).
        if let Ok(old) = std::fs::metadata(path) {
            std::fs::set_permissions(&tmp, old.permissions())?;
        }
        std::fs::rename(&tmp, path)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// A multiply-rotate hasher (FxHash's recipe) for small integer keys such as voxel indices:
/// several times faster than the default SipHash, and hash flooding is no concern for keys
/// computed from our own geometry.
#[derive(Clone, Copy, Default)]
pub struct FastHasher(u64);

impl std::hash::Hasher for FastHasher {
    fn finish(&self) -> u64 {
        self.0
    }

    fn write(&mut self, bytes: &[u8]) {
        for chunk in bytes.chunks(8) {
            let mut word = [0u8; 8];
            word[..chunk.len()].copy_from_slice(chunk);
            self.write_u64(u64::from_le_bytes(word));
        }
    }

    fn write_u64(&mut self, v: u64) {
        self.0 = (self.0.rotate_left(5) ^ v).wrapping_mul(0x517c_c1b7_2722_0a95);
    }

    fn write_i32(&mut self, v: i32) {
        self.write_u64(v as u32 as u64);
    }

    fn write_usize(&mut self, v: usize) {
        self.write_u64(v as u64);
    }
}

/// A `HashMap` / `HashSet` with [`FastHasher`].
pub type FastMap<K, V> = std::collections::HashMap<K, V, std::hash::BuildHasherDefault<FastHasher>>;
pub type FastSet<K> = std::collections::HashSet<K, std::hash::BuildHasherDefault<FastHasher>>;

/// Seconds since 1970-01-01 UTC, now.
fn unix_secs_now() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs() as i64)
}

/// Today's date (UTC) as YYYY-MM-DD.
pub fn today_utc() -> String {
    let (y, m, d) = civil_from_days(unix_secs_now().div_euclid(86_400));
    format!("{y:04}-{m:02}-{d:02}")
}

/// Now (UTC) as an ISO 8601 time, YYYY-MM-DDTHH:MM:SSZ.
pub fn now_utc() -> String {
    utc_time(unix_secs_now())
}

/// `secs` since 1970-01-01 UTC as YYYY-MM-DDTHH:MM:SSZ.
fn utc_time(secs: i64) -> String {
    let (y, m, d) = civil_from_days(secs.div_euclid(86_400));
    let s = secs.rem_euclid(86_400);
    format!(
        "{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02}Z",
        s / 3600,
        s / 60 % 60,
        s % 60
    )
}

/// Proleptic Gregorian date of a day count since 1970-01-01 (Howard Hinnant's algorithm).
fn civil_from_days(z: i64) -> (i64, u32, u32) {
    let z = z + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    let y = yoe + era * 400 + i64::from(m <= 2);
    (y, m, d)
}

/// Give the memory the program has freed back to the operating system. glibc's allocator
/// keeps freed chunks in its per-thread arenas, so a stage that builds and drops large
/// temporary data (the pipeline's hand-eye start: decoded images, a LiDAR map and its k-d
/// tree) would otherwise leave them counted in the process's memory while UniCal allocates
/// its tables beside them. A no-op on other allocators and systems.
pub fn release_freed() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    #[allow(unsafe_code)]
    // SAFETY: malloc_trim only returns free memory at the top of the heap and whole free
    // pages inside it to the system; it touches no live allocation.
    unsafe {
        libc::malloc_trim(0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn civil_dates_and_times_are_right() {
        assert_eq!(civil_from_days(0), (1970, 1, 1));
        assert_eq!(civil_from_days(19_675), (2023, 11, 14));
        assert_eq!(civil_from_days(11_016), (2000, 2, 29));
        assert_eq!(utc_time(0), "1970-01-01T00:00:00Z");
        assert_eq!(utc_time(19_675 * 86_400 + 3_723), "2023-11-14T01:02:03Z");
        assert_eq!(utc_time(-1), "1969-12-31T23:59:59Z");
    }

    #[test]
    fn writes_and_replaces() {
        let dir = std::env::temp_dir().join(format!("rigcal-atomic-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("a.txt");
        write_atomic(&p, b"one").unwrap();
        write_atomic(&p, b"two").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"two");
        // No temporary files are left behind.
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[cfg(unix)]
    #[test]
    fn a_link_stays_a_link_and_a_device_is_written_to_not_replaced() {
        let dir = std::env::temp_dir().join(format!("rigcal-atomic-link-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let target = dir.join("target.yaml");
        let link = dir.join("link.yaml");
        std::fs::write(&target, b"old").unwrap();
        std::os::unix::fs::symlink("target.yaml", &link).unwrap();
        write_atomic(&link, b"new").unwrap();
        assert!(
            std::fs::symlink_metadata(&link)
                .unwrap()
                .file_type()
                .is_symlink()
        );
        assert_eq!(std::fs::read(&target).unwrap(), b"new");
        // A link whose target does not exist yet creates the target.
        let dangling = dir.join("dangling.yaml");
        std::os::unix::fs::symlink("made.yaml", &dangling).unwrap();
        write_atomic(&dangling, b"made").unwrap();
        assert_eq!(std::fs::read(dir.join("made.yaml")).unwrap(), b"made");
        assert!(
            std::fs::symlink_metadata(&dangling)
                .unwrap()
                .file_type()
                .is_symlink()
        );
        // /dev/null is written to, not replaced (asserted on the resolution only, so a
        // regression cannot replace the machine's /dev/null when tests run as root).
        let null = Path::new("/dev/null");
        if null.exists() {
            assert_eq!(
                output_target(null).unwrap(),
                OutputTarget::Direct(null.into())
            );
        }
        // Two names of one file not written yet are the same file.
        assert!(same_file(
            &dir.join("new.mcap"),
            &dir.join(".").join("new.mcap")
        ));
        assert!(!same_file(&dir.join("new.mcap"), &dir.join("new.yaml")));
        // A directory is refused, naming it.
        let e = write_atomic(&dir, b"x").unwrap_err();
        assert!(e.to_string().contains("is a directory"), "{e}");
        assert!(same_file(&link, &target) && !same_file(&link, &dangling));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
