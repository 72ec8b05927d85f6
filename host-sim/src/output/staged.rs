//! Output files that are never half-written: each is written to a temporary file beside
//! its target and renamed over it only when complete.
//!
//! Why: a run that is refused (a typo in the scenario's name), fails mid-way (a CAN bus
//! error) or is interrupted must leave whatever the user already had at that path — a
//! committed figure, last week's trace — byte-identical. Creating the target up front
//! to check that it can be written (what this crate did before) truncates it first.
//! Instead a [`Staged`] file creates its temporary file at once (so an output that cannot
//! be written is still refused before anything runs), and the target is only touched by
//! one `rename(2)`, which POSIX makes atomic within a file system: readers see the old
//! file or the new one, never a mix. A `Staged` dropped without [`Staged::commit`]
//! removes its temporary file.
//!
//! A target that is not a regular file — `/dev/stdout`, `/dev/null`, a named pipe — is
//! written to directly: it cannot be half-written in the sense above, and renaming over
//! it would replace the device with a file. A symbolic link is followed, so the file it
//! points to is the one replaced.

use std::fs::File;
use std::io;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU32, Ordering};

/// Distinguishes the temporary files of one process (two outputs in one directory).
static NEXT: AtomicU32 = AtomicU32::new(0);

/// An output being written: a temporary file beside `target`, renamed over it on
/// [`Staged::commit`].
#[derive(Debug)]
pub struct Staged {
    target: PathBuf,
    /// The file written: beside the target, or the target itself when it is a device.
    temp: PathBuf,
    file: Option<File>,
    committed: bool,
    /// The target is written directly (it is not a regular file).
    direct: bool,
}

impl Staged {
    /// Creates the temporary file beside `target` (the target itself is not touched).
    /// Fails as creating `target` would: a missing directory, no permission, a path that
    /// names a directory.
    pub fn create(target: &Path) -> io::Result<Self> {
        if target.is_dir() {
            return Err(io::Error::new(
                io::ErrorKind::IsADirectory,
                "is a directory",
            ));
        }
        // Follow a link to the file it names.
        let target = match std::fs::canonicalize(target) {
            Ok(real) if target.is_symlink() => real,
            _ => target.to_path_buf(),
        };
        let target = target.as_path();
        if target.exists() && !target.is_file() {
            let file = std::fs::OpenOptions::new().write(true).open(target)?;
            return Ok(Self {
                target: target.to_path_buf(),
                temp: target.to_path_buf(),
                file: Some(file),
                committed: false,
                direct: true,
            });
        }
        let name = target
            .file_name()
            .ok_or_else(|| io::Error::new(io::ErrorKind::InvalidInput, "no file name"))?;
        let dir = match target.parent() {
            Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
            _ => PathBuf::from("."),
        };
        // Keep the extension last: writers that pick a format by it (a PNG or SVG plot)
        // see the target's.
        let ext = target
            .extension()
            .map(|e| format!(".{}", e.to_string_lossy()))
            .unwrap_or_default();
        let n = NEXT.fetch_add(1, Ordering::Relaxed);
        let temp = dir.join(format!(
            ".{}.{}-{n}.part{ext}",
            name.to_string_lossy(),
            std::process::id()
        ));
        let file = File::create(&temp)?;
        Ok(Self {
            target: target.to_path_buf(),
            temp,
            file: Some(file),
            committed: false,
            direct: false,
        })
    }

    /// The temporary file's path, for writers that open a path themselves (it has the
    /// target's extension).
    pub fn temp_path(&self) -> &Path {
        &self.temp
    }

    /// The target's path.
    pub fn target(&self) -> &Path {
        &self.target
    }

    /// The temporary file, for writing (`None` once taken).
    pub fn take_file(&mut self) -> Option<File> {
        self.file.take()
    }

    /// Writes `bytes` as the whole content.
    pub fn write_all(&mut self, bytes: &[u8]) -> io::Result<()> {
        use std::io::Write;
        let mut f = match self.file.take() {
            Some(f) if self.direct => f,
            _ => File::create(&self.temp)?,
        };
        f.write_all(bytes)?;
        self.file = Some(f);
        Ok(())
    }

    /// Flushes the content to disk and renames it over the target.
    pub fn commit(mut self) -> io::Result<()> {
        if self.direct {
            self.committed = true;
            return Ok(());
        }
        if let Some(f) = self.file.take() {
            f.sync_all()?;
        } else {
            File::open(&self.temp)?.sync_all()?;
        }
        std::fs::rename(&self.temp, &self.target)?;
        self.committed = true;
        Ok(())
    }
}

impl Drop for Staged {
    fn drop(&mut self) {
        if !self.committed && !self.direct {
            let _ = std::fs::remove_file(&self.temp);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("staged-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn listing(d: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(d)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    #[test]
    fn the_target_changes_only_on_commit() {
        let d = dir("commit");
        let target = d.join("fig.png");
        std::fs::write(&target, b"old").unwrap();
        let mut s = Staged::create(&target).unwrap();
        assert_eq!(s.temp_path().extension().unwrap(), "png");
        s.write_all(b"new").unwrap();
        assert_eq!(std::fs::read(&target).unwrap(), b"old");
        s.commit().unwrap();
        assert_eq!(std::fs::read(&target).unwrap(), b"new");
        assert_eq!(listing(&d), vec!["fig.png"]);
    }

    #[test]
    fn a_dropped_output_leaves_the_target_and_no_temporary_file() {
        let d = dir("drop");
        let target = d.join("trace.csv");
        std::fs::write(&target, b"kept").unwrap();
        let mut s = Staged::create(&target).unwrap();
        s.write_all(b"half").unwrap();
        drop(s);
        assert_eq!(std::fs::read(&target).unwrap(), b"kept");
        assert_eq!(listing(&d), vec!["trace.csv"]);
    }

    #[test]
    fn devices_are_written_directly_and_links_are_followed() {
        let mut s = Staged::create(Path::new("/dev/null")).unwrap();
        assert_eq!(s.temp_path(), Path::new("/dev/null"));
        s.write_all(b"gone").unwrap();
        s.commit().unwrap();
        let meta = std::fs::metadata("/dev/null").unwrap();
        assert!(!meta.is_file(), "/dev/null is still a device");
        let d = dir("link");
        let real = d.join("real.csv");
        std::fs::write(&real, b"old").unwrap();
        let link = d.join("link.csv");
        std::os::unix::fs::symlink(&real, &link).unwrap();
        let mut s = Staged::create(&link).unwrap();
        s.write_all(b"new").unwrap();
        s.commit().unwrap();
        assert!(link.is_symlink(), "the link stays a link");
        assert_eq!(std::fs::read(&real).unwrap(), b"new");
    }

    #[test]
    fn unwritable_targets_are_refused_at_once() {
        let d = dir("refuse");
        assert!(Staged::create(&d.join("no-such-dir").join("x.csv")).is_err());
        assert!(Staged::create(&d).is_err());
        assert!(listing(&d).is_empty());
    }
}
