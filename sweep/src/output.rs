//! Writing output files atomically: write a temporary file in the same directory (so the
//! rename stays on one file system), flush it to disk, then rename it over the target. A
//! reader never sees half a file, and an interrupted run leaves the previous file (or none).

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

/// What can go wrong writing a file atomically; every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    #[error("{} is not a file path", path.display())]
    NotAFilePath { path: PathBuf },
    #[error("cannot create {}", path.display())]
    Create {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("cannot write {}", path.display())]
    Write {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("cannot rename {} to {}", from.display(), to.display())]
    Rename {
        from: PathBuf,
        to: PathBuf,
        #[source]
        source: std::io::Error,
    },
}

/// Replace `path` with what `fill` writes; on any error nothing is left behind. `fill` may
/// fail with the caller's own error type, which also carries this module's errors.
pub fn write_atomically_with<T, E: From<OutputError>>(
    path: &Path,
    fill: impl FnOnce(&mut BufWriter<File>) -> Result<T, E>,
) -> Result<T, E> {
    let file = AtomicFile::create(path)?;
    let mut writer = BufWriter::with_capacity(1 << 20, file.handle()?);
    let value = fill(&mut writer)?;
    writer.into_inner().map_err(|e| OutputError::Write {
        path: file.temp.clone(),
        source: e.into_error(),
    })?;
    file.commit()?;
    Ok(value)
}

/// A file that becomes `path` only when committed, for a writer that must own its
/// destination or seek in it: the temporary sibling, created at once; [`AtomicFile::commit`]
/// flushes it to disk and renames it over `path`; dropped uncommitted, it is removed.
pub struct AtomicFile {
    temp: PathBuf,
    target: PathBuf,
    file: Option<File>,
}

impl AtomicFile {
    pub fn create(path: &Path) -> Result<AtomicFile, OutputError> {
        let temp = temp_path_beside(path)?;
        let file = File::create(&temp).map_err(|source| OutputError::Create {
            path: temp.clone(),
            source,
        })?;
        Ok(AtomicFile {
            temp,
            target: path.to_path_buf(),
            file: Some(file),
        })
    }

    /// Another handle on the temporary file (sharing its position), to write it through.
    pub fn handle(&self) -> Result<File, OutputError> {
        let file = self.file.as_ref().expect("an uncommitted file");
        file.try_clone().map_err(|source| OutputError::Create {
            path: self.temp.clone(),
            source,
        })
    }

    /// Flush the file to disk and rename it over the target (the writers through
    /// [`AtomicFile::handle`] must have flushed).
    pub fn commit(mut self) -> Result<(), OutputError> {
        let file = self.file.take().expect("an uncommitted file");
        let outcome = file
            .sync_all()
            .map_err(|source| OutputError::Write {
                path: self.temp.clone(),
                source,
            })
            .and_then(|()| {
                std::fs::rename(&self.temp, &self.target).map_err(|source| OutputError::Rename {
                    from: self.temp.clone(),
                    to: self.target.clone(),
                    source,
                })
            });
        if outcome.is_err() {
            // Best effort: the original error matters more.
            let _ = std::fs::remove_file(&self.temp);
        }
        outcome
    }
}

impl Drop for AtomicFile {
    fn drop(&mut self) {
        if self.file.take().is_some() {
            // Uncommitted: best effort, nothing left behind.
            let _ = std::fs::remove_file(&self.temp);
        }
    }
}

/// Replace `path` with `contents` atomically.
pub fn write_atomically(path: &Path, contents: &[u8]) -> Result<(), OutputError> {
    write_atomically_with(path, |w| {
        w.write_all(contents).map_err(|source| OutputError::Write {
            path: path.to_path_buf(),
            source,
        })
    })
}

/// `dir/.name.tmp-PID`: hidden, unique per process, in the target's own directory.
fn temp_path_beside(path: &Path) -> Result<PathBuf, OutputError> {
    let name = path.file_name().ok_or_else(|| OutputError::NotAFilePath {
        path: path.to_path_buf(),
    })?;
    let mut temp_name = std::ffi::OsString::from(".");
    temp_name.push(name);
    temp_name.push(format!(".tmp-{}", std::process::id()));
    Ok(path.with_file_name(temp_name))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn replaces_contents_and_leaves_no_temporary_file() {
        let temp = crate::test_dir("atomic");
        let dir = temp.path();
        let path = dir.join("out.txt");
        std::fs::write(&path, "old contents that are longer").unwrap();
        write_atomically(&path, b"new").unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "new");
        let names: Vec<_> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, ["out.txt"]);
    }

    #[test]
    fn a_failed_fill_leaves_the_old_file_and_no_temporary() {
        let temp = crate::test_dir("atomic-fail");
        let dir = temp.path();
        let path = dir.join("out.txt");
        std::fs::write(&path, "old").unwrap();
        let failed: Result<(), Box<dyn std::error::Error>> = write_atomically_with(&path, |w| {
            w.write_all(b"half")?;
            Err("interrupted".into())
        });
        assert_eq!(failed.unwrap_err().to_string(), "interrupted");
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "old");
        assert_eq!(std::fs::read_dir(dir).unwrap().count(), 1);
    }

    #[test]
    fn an_uncommitted_file_leaves_nothing_and_a_committed_one_replaces() {
        let temp = crate::test_dir("atomic-file");
        let dir = temp.path();
        let path = dir.join("out.bin");
        std::fs::write(&path, "old").unwrap();
        let file = AtomicFile::create(&path).unwrap();
        file.handle().unwrap().write_all(b"dropped").unwrap();
        drop(file);
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "old");
        assert_eq!(std::fs::read_dir(dir).unwrap().count(), 1);
        let file = AtomicFile::create(&path).unwrap();
        file.handle().unwrap().write_all(b"new").unwrap();
        file.commit().unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "new");
        assert_eq!(std::fs::read_dir(dir).unwrap().count(), 1);
    }

    #[test]
    fn missing_directory_is_an_error_naming_the_path() {
        let temp = crate::test_dir("atomic-missing");
        let dir = temp.path();
        let path = dir.join("no-such-dir").join("out.txt");
        let err = write_atomically(&path, b"x").unwrap_err();
        assert!(matches!(err, OutputError::Create { .. }), "{err:?}");
        assert!(err.to_string().contains("no-such-dir"), "{err}");
    }
}
