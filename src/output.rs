//! Writing output files atomically: write a temporary file in the same directory (so the
//! rename stays on one file system), flush it to disk, then rename it over the target. A
//! reader never sees half a file, and an interrupted run leaves the previous file (or none).

use anyhow::{Context, Result};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

/// Replace `path` with what `fill` writes; on any error nothing is left behind.
pub fn write_atomically_with<T>(
    path: &Path,
    fill: impl FnOnce(&mut BufWriter<std::fs::File>) -> Result<T>,
) -> Result<T> {
    let temp = temp_path_beside(path)?;
    let outcome = (|| {
        let file = std::fs::File::create(&temp)
            .with_context(|| format!("cannot create {}", temp.display()))?;
        let mut writer = BufWriter::with_capacity(1 << 20, file);
        let value = fill(&mut writer)?;
        writer
            .into_inner()
            .map_err(|e| e.into_error())
            .and_then(|file| file.sync_all())
            .with_context(|| format!("cannot write {}", temp.display()))?;
        std::fs::rename(&temp, path)
            .with_context(|| format!("cannot rename {} to {}", temp.display(), path.display()))?;
        Ok(value)
    })();
    if outcome.is_err() {
        // Best effort: do not leave the temporary file behind; the original error matters more.
        let _ = std::fs::remove_file(&temp);
    }
    outcome
}

/// Replace `path` with `contents` atomically.
pub fn write_atomically(path: &Path, contents: &[u8]) -> Result<()> {
    write_atomically_with(path, |w| Ok(w.write_all(contents)?))
}

/// `dir/.name.tmp-PID`: hidden, unique per process, in the target's own directory.
fn temp_path_beside(path: &Path) -> Result<PathBuf> {
    let name = path
        .file_name()
        .with_context(|| format!("{} is not a file path", path.display()))?;
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
        let temp = crate::sweep::test_dir("atomic");
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
        let temp = crate::sweep::test_dir("atomic-fail");
        let dir = temp.path();
        let path = dir.join("out.txt");
        std::fs::write(&path, "old").unwrap();
        let failed: Result<()> = write_atomically_with(&path, |w| {
            w.write_all(b"half")?;
            anyhow::bail!("interrupted")
        });
        assert!(failed.is_err());
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "old");
        assert_eq!(std::fs::read_dir(dir).unwrap().count(), 1);
    }

    #[test]
    fn missing_directory_is_an_error_naming_the_path() {
        let temp = crate::sweep::test_dir("atomic-missing");
        let dir = temp.path();
        let path = dir.join("no-such-dir").join("out.txt");
        let err = format!("{:#}", write_atomically(&path, b"x").unwrap_err());
        assert!(err.contains("no-such-dir"), "{err}");
    }
}
