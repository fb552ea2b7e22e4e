//! Writing output files atomically: write a temporary file in the same directory (so the
//! rename stays on one file system), flush it to disk, then rename it over the target. A
//! reader never sees half a file, and an interrupted run leaves the previous file (or none).

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Mutex, MutexGuard};

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
    #[error(
        "{}: not a regular file (a device, a pipe or a directory): outputs are written whole beside their path and renamed over it, which would replace it",
        path.display()
    )]
    NotARegularFile { path: PathBuf },
    #[error("{}: this command reads it: an output there would overwrite its own input", path.display())]
    WouldOverwriteInput { path: PathBuf },
    #[error("{}: two of this command's outputs are asked for there: give each its own path", path.display())]
    TwoOutputsOnePath { path: PathBuf },
    #[error("cannot rename {} to {}", from.display(), to.display())]
    Rename {
        from: PathBuf,
        to: PathBuf,
        #[source]
        source: std::io::Error,
    },
}

/// Temporary files being written now: what [`remove_temporaries`] removes when the process
/// is interrupted (the binary calls it from its signal handler).
static LIVE: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

/// The files this process reads (canonical paths): no output replaces one of them.
static INPUTS: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

/// `path` is an input of this process: an output to it is refused.
pub fn note_input(path: &Path) {
    if let Ok(path) = std::fs::canonicalize(path) {
        let mut inputs = lock(&INPUTS);
        if !inputs.contains(&path) {
            inputs.push(path);
        }
    }
}

/// Scratch directories alive now, removed with the temporary files.
static LIVE_DIRS: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

/// Set once [`remove_temporaries`] has begun: no temporary file or scratch directory is
/// created from then on.
static INTERRUPTED: AtomicBool = AtomicBool::new(false);

/// Whether [`remove_temporaries`] has begun: the process is being ended by a signal.
pub fn stopping() -> bool {
    INTERRUPTED.load(Ordering::SeqCst)
}

/// `list` locked, whatever a panicking holder left.
fn lock(list: &Mutex<Vec<PathBuf>>) -> MutexGuard<'_, Vec<PathBuf>> {
    list.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}

/// Remove every temporary file this process is writing, and its scratch directories (for a
/// signal handler, just before the process exits: the work they belong to will never
/// finish). The work goes on in other threads meanwhile: a temporary is created under the
/// lock of its list, which this takes before saying no more may be, so one created first
/// is listed here and one after fails. (Without that, a scratch directory's removal could
/// meet a file created in it after it was listed, and leave the directory behind.)
pub fn remove_temporaries() {
    let (files, dirs) = {
        let (mut files, mut dirs) = (lock(&LIVE), lock(&LIVE_DIRS));
        INTERRUPTED.store(true, Ordering::SeqCst);
        (std::mem::take(&mut *files), std::mem::take(&mut *dirs))
    };
    for path in files {
        let _ = std::fs::remove_file(path);
    }
    for path in dirs {
        let _ = std::fs::remove_dir_all(path);
    }
}

/// The error a temporary created after [`remove_temporaries`] began gets.
fn interrupted(path: &Path) -> OutputError {
    OutputError::Create {
        path: path.to_path_buf(),
        source: std::io::Error::new(std::io::ErrorKind::Interrupted, "the process is stopping"),
    }
}

/// A directory for intermediate files, removed with everything in it when dropped, or by
/// [`remove_temporaries`] when the process is interrupted.
pub struct ScratchDir {
    path: PathBuf,
}

impl ScratchDir {
    /// A new directory `PREFIX-PID` under the system's temporary directory; those that
    /// earlier, killed processes left there under the same prefix are removed first.
    pub fn create(prefix: &str) -> Result<ScratchDir, OutputError> {
        let temp = std::env::temp_dir();
        let path = temp.join(format!("{prefix}-{}", std::process::id()));
        remove_left_by_gone_processes(&temp, &format!("{prefix}-"), |dir| {
            let _ = std::fs::remove_dir_all(dir);
        });
        let mut live = lock(&LIVE_DIRS);
        if INTERRUPTED.load(Ordering::SeqCst) {
            return Err(interrupted(&path));
        }
        std::fs::create_dir_all(&path).map_err(|source| OutputError::Create {
            path: path.clone(),
            source,
        })?;
        live.push(path.clone());
        Ok(ScratchDir { path })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }
}

impl Drop for ScratchDir {
    fn drop(&mut self) {
        if let Ok(mut live) = LIVE_DIRS.lock() {
            live.retain(|p| p != &self.path);
        }
        let _ = std::fs::remove_dir_all(&self.path);
    }
}

/// Replace `path` with what `fill` writes; on any error (or panic) nothing is left behind.
/// `fill` may fail with the caller's own error type, which also carries this module's errors.
/// Temporaries that earlier, killed processes left beside `path` are removed first.
pub fn write_atomically_with<T, E: From<OutputError>>(
    path: &Path,
    fill: impl FnOnce(&mut BufWriter<File>) -> Result<T, E>,
) -> Result<T, E> {
    let (value, file) = write_finished_with(path, fill)?;
    commit_together(vec![file])?;
    Ok(value)
}

/// [`write_atomically_with`] but for the rename: the file, written and flushed to disk, to
/// be renamed into place with the command's other outputs ([`commit_together`]).
pub fn write_finished_with<T, E: From<OutputError>>(
    path: &Path,
    fill: impl FnOnce(&mut BufWriter<File>) -> Result<T, E>,
) -> Result<(T, Finished), E> {
    let file = AtomicFile::create(path)?;
    let mut writer = BufWriter::with_capacity(1 << 20, file.handle()?);
    let value = fill(&mut writer)?;
    writer.into_inner().map_err(|e| OutputError::Write {
        path: file.temp.clone(),
        source: e.into_error(),
    })?;
    Ok((value, file.finish()?))
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
    /// Temporaries that earlier, killed processes left beside `path` are removed first; the
    /// new one is listed for [`remove_temporaries`] until it is committed or dropped.
    pub fn create(path: &Path) -> Result<AtomicFile, OutputError> {
        let path = &destination(path)?;
        let temp = temp_path_beside(path)?;
        remove_stale_temporaries(path);
        let mut live = lock(&LIVE);
        if INTERRUPTED.load(Ordering::SeqCst) {
            return Err(interrupted(&temp));
        }
        if live.contains(&temp) {
            // Another output of this process is being written there (its temporary is
            // named by the path): the later rename would replace it.
            return Err(OutputError::TwoOutputsOnePath {
                path: path.to_path_buf(),
            });
        }
        // Named by the path asked for: the temporary beside it is this module's business.
        let file = File::create(&temp).map_err(|source| OutputError::Create {
            path: path.to_path_buf(),
            source,
        })?;
        live.push(temp.clone());
        drop(live);
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
    pub fn commit(self) -> Result<(), OutputError> {
        commit_together(vec![self.finish()?])
    }

    /// Flush the file to disk, to be renamed over the target with the command's other
    /// outputs ([`commit_together`]) once they are all written too (the writers through
    /// [`AtomicFile::handle`] must have flushed).
    pub fn finish(mut self) -> Result<Finished, OutputError> {
        let file = self.file.take().expect("an uncommitted file");
        // Taken out, the path is left for [`Finished`] to remove or rename.
        let temp = std::mem::take(&mut self.temp);
        let finished = Finished {
            temp,
            target: std::mem::take(&mut self.target),
        };
        file.sync_all().map_err(|source| OutputError::Write {
            path: finished.temp.clone(),
            source,
        })?;
        Ok(finished)
    }
}

/// An output written whole and flushed to disk, waiting beside its path to be renamed over
/// it with the command's other outputs ([`commit_together`]); dropped uncommitted (an
/// error, or another output that failed), it is removed.
#[derive(Debug)]
pub struct Finished {
    temp: PathBuf,
    target: PathBuf,
}

impl Drop for Finished {
    fn drop(&mut self) {
        if self.temp.as_os_str().is_empty() {
            return; // renamed into place
        }
        if let Ok(mut live) = LIVE.lock() {
            live.retain(|p| p != &self.temp);
        }
        let _ = std::fs::remove_file(&self.temp);
    }
}

/// Rename every one of a command's outputs over its target, all or none as far as an
/// interrupt goes: under the lock [`remove_temporaries`] takes first, so that a signal that
/// comes before finds them all still temporaries (and removes them), and one that comes
/// during waits until they are all in place. (Renamed one by one as each was done, an
/// interrupt between two renames had left the first output without the others.) A rename
/// that fails stops the rest, which are removed; those before it stay in place.
pub fn commit_together(files: Vec<Finished>) -> Result<(), OutputError> {
    if files.is_empty() {
        return Ok(());
    }
    // Out of their guards, whose drop would take the lock held below.
    let files: Vec<(PathBuf, PathBuf)> = files
        .into_iter()
        .map(|mut file| {
            (
                std::mem::take(&mut file.temp),
                std::mem::take(&mut file.target),
            )
        })
        .collect();
    let mut live = lock(&LIVE);
    live.retain(|listed| files.iter().all(|(temp, _)| temp != listed));
    let mut outcome = match INTERRUPTED.load(Ordering::SeqCst) {
        true => Err(interrupted(files.first().map_or(Path::new(""), |f| &f.1))),
        false => Ok(()),
    };
    let mut renamed = Vec::with_capacity(files.len());
    for (temp, target) in files {
        if outcome.is_ok() {
            match std::fs::rename(&temp, &target) {
                Ok(()) => {
                    renamed.push(target);
                    continue;
                }
                Err(source) => {
                    outcome = Err(OutputError::Rename {
                        from: temp.clone(),
                        to: target,
                        source,
                    })
                }
            }
        }
        let _ = std::fs::remove_file(&temp);
    }
    drop(live);
    for target in &renamed {
        sync_directory_of(target);
    }
    outcome
}

impl Drop for AtomicFile {
    fn drop(&mut self) {
        if self.file.is_none() {
            return; // finished: its temporary is [`Finished`]'s
        }
        if let Ok(mut live) = LIVE.lock() {
            live.retain(|p| p != &self.temp);
        }
        if self.file.take().is_some() {
            // Uncommitted (an error or a panic): best effort, nothing left behind.
            let _ = std::fs::remove_file(&self.temp);
        }
    }
}

/// Flush `path`'s directory to disk, so that a rename into it outlives a power loss as the
/// file's contents do (best effort: not every system opens a directory as a file).
fn sync_directory_of(path: &Path) {
    if let Ok(directory) = File::open(directory_of(path)) {
        let _ = directory.sync_all();
    }
}

/// The directory `path` is in (`.` for a bare file name).
fn directory_of(path: &Path) -> &Path {
    match path.parent() {
        Some(parent) if !parent.as_os_str().is_empty() => parent,
        _ => Path::new("."),
    }
}

/// Where an output to `path` goes: a symbolic link's file (the link stays), and only a
/// regular file or none (renamed over, a device such as /dev/full, written as root, had
/// become a regular file).
fn destination(path: &Path) -> Result<PathBuf, OutputError> {
    let target = std::fs::canonicalize(path).unwrap_or_else(|_| not_there_yet(path));
    match std::fs::metadata(&target) {
        Ok(metadata) if !metadata.is_file() => Err(OutputError::NotARegularFile {
            path: path.to_path_buf(),
        }),
        Ok(_) if lock(&INPUTS).contains(&target) => Err(OutputError::WouldOverwriteInput {
            path: path.to_path_buf(),
        }),
        _ => Ok(target),
    }
}

/// Links followed to a file not there yet, at most: as many as the system follows.
const MAX_LINKS: usize = 40;

/// Where a file not there yet will be: links to it followed (a link's target taken from the
/// link's directory), then its directory's canonical path and its name, so that one file
/// spelt two ways (`same.out`, `./same.out`, a link to it) is one destination. (A link's
/// target had been taken as written: `lnk -> r.jsonl` and `r.jsonl` were two destinations,
/// and a sweep's chart through the link replaced its results.)
fn not_there_yet(path: &Path) -> PathBuf {
    let mut path = path.to_path_buf();
    for _ in 0..MAX_LINKS {
        match std::fs::read_link(&path) {
            Ok(link) => path = directory_of(&path).join(link),
            Err(_) => break,
        }
    }
    match (std::fs::canonicalize(directory_of(&path)), path.file_name()) {
        (Ok(directory), Some(name)) => directory.join(name),
        _ => path,
    }
}

/// Remove `.NAME.tmp-PID` files beside `path` whose process no longer exists (on systems
/// with `/proc`, where that can be told; elsewhere nothing is removed).
fn remove_stale_temporaries(path: &Path) {
    let Some(name) = path.file_name() else {
        return;
    };
    let prefix = format!(".{}.tmp-", name.to_string_lossy());
    remove_left_by_gone_processes(directory_of(path), &prefix, |file| {
        let _ = std::fs::remove_file(file);
    });
}

/// `remove` each entry of `dir` named `PREFIX` and a process id whose process no longer
/// exists (on systems with `/proc`, where that can be told; elsewhere none).
fn remove_left_by_gone_processes(dir: &Path, prefix: &str, remove: impl Fn(&Path)) {
    if !Path::new("/proc/self").exists() {
        return;
    }
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let file_name = entry.file_name();
        let Some(pid) = file_name
            .to_str()
            .and_then(|n| n.strip_prefix(prefix))
            .and_then(|pid| pid.parse::<u32>().ok())
        else {
            continue;
        };
        let alive = pid == std::process::id() || Path::new(&format!("/proc/{pid}")).exists();
        if !alive {
            remove(&entry.path());
        }
    }
}

/// Whether an output could be written to `path`, asked before the work that makes it: a
/// path [`AtomicFile::create`] takes (no device, no input of this process) in an existing
/// directory. (Its directory's permissions are left to the write: root passes them.)
pub fn check_writable(path: &Path) -> Result<(), OutputError> {
    let path = destination(path)?;
    temp_path_beside(&path)?;
    match std::fs::metadata(directory_of(&path)) {
        Ok(metadata) if metadata.is_dir() => Ok(()),
        Ok(_) => Err(OutputError::Create {
            path,
            source: std::io::Error::new(
                std::io::ErrorKind::NotADirectory,
                "its parent is not a directory",
            ),
        }),
        Err(source) => Err(OutputError::Create { path, source }),
    }
}

/// Refuse two of a command's outputs at one path, however each is spelt, before the work
/// that makes them: written one after the other, the later would replace the earlier (a
/// sweep's chart had replaced its own results file). Each path as [`check_writable`] takes it.
pub fn check_distinct(paths: &[&Path]) -> Result<(), OutputError> {
    let mut destinations = Vec::with_capacity(paths.len());
    for path in paths {
        let destination = destination(path)?;
        if destinations.contains(&destination) {
            return Err(OutputError::TwoOutputsOnePath {
                path: path.to_path_buf(),
            });
        }
        destinations.push(destination);
    }
    Ok(())
}

/// Replace `path` with `contents` atomically.
pub fn write_atomically(path: &Path, contents: &[u8]) -> Result<(), OutputError> {
    commit_together(vec![write_finished(path, contents)?])
}

/// `contents` written beside `path` and flushed to disk, to be renamed into place with the
/// command's other outputs ([`commit_together`]).
pub fn write_finished(path: &Path, contents: &[u8]) -> Result<Finished, OutputError> {
    let ((), file) = write_finished_with(path, |w| {
        w.write_all(contents).map_err(|source| OutputError::Write {
            path: path.to_path_buf(),
            source,
        })
    })?;
    Ok(file)
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
    #[cfg(unix)]
    fn two_outputs_at_one_file_are_refused_however_spelt_links_not_there_yet_too() {
        let dir = tempfile::tempdir().unwrap();
        let results = dir.path().join("r.jsonl");
        // Links to a file not there yet: by a name relative to the link, through a
        // directory and back, and through another link.
        std::fs::create_dir(dir.path().join("sub")).unwrap();
        let links = [("lnk.svg", "r.jsonl"), ("back.svg", "sub/../r.jsonl")];
        for (link, to) in links {
            std::os::unix::fs::symlink(to, dir.path().join(link)).unwrap();
        }
        std::os::unix::fs::symlink("lnk.svg", dir.path().join("chain.svg")).unwrap();
        for spelt in [
            "lnk.svg",
            "back.svg",
            "chain.svg",
            "./r.jsonl",
            "sub/../r.jsonl",
        ] {
            let other = dir.path().join(spelt);
            let error = check_distinct(&[&results, &other]).expect_err(spelt);
            assert!(
                matches!(error, OutputError::TwoOutputsOnePath { .. }),
                "{spelt}: {error}"
            );
        }
        let apart = dir.path().join("r.svg");
        assert!(check_distinct(&[&results, &apart]).is_ok());
    }

    #[test]
    #[cfg(unix)]
    fn a_device_is_refused_a_link_followed_and_an_input_kept() {
        // Renamed over, /dev/full (written as root) had become a regular file; a pipe stands
        // in for a device here.
        let dir = tempfile::tempdir().unwrap();
        let pipe = dir.path().join("pipe");
        let made = std::process::Command::new("mkfifo").arg(&pipe).status();
        if made.is_ok_and(|status| status.success()) {
            let error = write_atomically(&pipe, b"x").expect_err("refused");
            assert!(
                matches!(error, OutputError::NotARegularFile { .. }),
                "{error}"
            );
            assert!(!std::fs::metadata(&pipe).unwrap().is_file());
        }
        // A link, to a file not there yet and then to one that is: the file is written, the
        // link stays a link.
        let (file, link) = (dir.path().join("file"), dir.path().join("link"));
        std::os::unix::fs::symlink(&file, &link).unwrap();
        for contents in ["first", "second"] {
            write_atomically(&link, contents.as_bytes()).unwrap();
            assert_eq!(std::fs::read_to_string(&file).unwrap(), contents);
            assert!(std::fs::symlink_metadata(&link)
                .unwrap()
                .file_type()
                .is_symlink());
        }
        // A file this process reads is not replaced, whatever path names it.
        let input = dir.path().join("input");
        std::fs::write(&input, "trace").unwrap();
        note_input(&input);
        let error = write_atomically(&dir.path().join(".").join("input"), b"x").expect_err("kept");
        assert!(
            matches!(error, OutputError::WouldOverwriteInput { .. }),
            "{error}"
        );
        assert_eq!(std::fs::read_to_string(&input).unwrap(), "trace");
    }

    #[test]
    fn an_output_is_checked_before_the_work_naming_the_path_asked_for() {
        let temp = crate::test_dir("check-writable");
        let dir = temp.path();
        assert!(check_writable(&dir.join("out.svg")).is_ok());
        let missing = dir.join("no-such-dir").join("out.svg");
        let error = check_writable(&missing).expect_err("no directory");
        assert!(
            matches!(&error, OutputError::Create { path, .. } if path == &missing),
            "{error}"
        );
        let file = dir.join("a-file");
        std::fs::write(&file, "x").unwrap();
        let error = check_writable(&file.join("out.svg")).expect_err("a file's child");
        assert!(matches!(error, OutputError::Create { .. }), "{error}");
        let error = check_writable(dir).expect_err("a directory");
        assert!(
            matches!(error, OutputError::NotARegularFile { .. }),
            "{error}"
        );
        // The write itself names the path asked for, not its temporary.
        let error = write_atomically(&missing, b"x").expect_err("no directory");
        assert!(
            error.to_string().ends_with("no-such-dir/out.svg"),
            "{error}"
        );
    }

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
    fn a_second_output_to_the_same_path_is_refused_and_the_first_stays_whole() {
        // `replay --vcd same.out --fst same.out` had written both through one temporary:
        // the first renamed it over same.out, the second found it gone and failed, leaving
        // same.out behind from a failed command.
        let temp = crate::test_dir("atomic-twice");
        let dir = temp.path();
        let path = dir.join("same.out");
        let first = AtomicFile::create(&path).unwrap();
        // The same file spelt another way: through a link to its directory (as `./same.out`
        // beside `same.out`, a new file's path had been taken as spelt).
        std::os::unix::fs::symlink(dir, dir.join("here")).unwrap();
        let second = AtomicFile::create(&dir.join("here").join("same.out"));
        assert!(matches!(
            second.err(),
            Some(OutputError::TwoOutputsOnePath { .. })
        ));
        first.handle().unwrap().write_all(b"first").unwrap();
        first.commit().unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "first");
        assert_eq!(
            std::fs::read_dir(dir).unwrap().count(),
            2,
            "same.out and the link"
        );
        // Once the first is through, the path is free again.
        AtomicFile::create(&path).unwrap();
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

    #[test]
    fn a_panicking_fill_leaves_no_temporary() {
        let temp = crate::test_dir("atomic-panic");
        let dir = temp.path();
        let path = dir.join("out.txt");
        let outcome = std::panic::catch_unwind(|| {
            let _: Result<(), OutputError> = write_atomically_with(&path, |w| {
                w.write_all(b"half").unwrap();
                panic!("the model failed")
            });
        });
        assert!(outcome.is_err());
        assert_eq!(std::fs::read_dir(dir).unwrap().count(), 0);
    }

    #[test]
    fn the_temporary_being_written_is_listed_for_the_signal_handler() {
        let temp = crate::test_dir("atomic-listed");
        let dir = temp.path().to_path_buf();
        let path = dir.join("out.txt");
        let mine = || -> Vec<PathBuf> {
            let live = LIVE.lock().unwrap();
            live.iter()
                .filter(|p| p.starts_with(&dir))
                .cloned()
                .collect()
        };
        write_atomically_with(&path, |w| -> Result<(), OutputError> {
            w.write_all(b"half").unwrap();
            // What `remove_temporaries` would remove if a signal came now (other tests'
            // writes run in parallel, so only this directory's entry is looked at).
            assert_eq!(
                mine(),
                [dir.join(".out.txt.tmp-".to_owned() + &std::process::id().to_string())]
            );
            Ok(())
        })
        .unwrap();
        assert!(mine().is_empty(), "a finished write is no longer listed");
    }

    #[test]
    fn the_next_write_removes_temporaries_of_processes_that_are_gone() {
        let temp = crate::test_dir("atomic-stale");
        let dir = temp.path();
        let path = dir.join("out.txt");
        // Linux process ids stay below 2^22 = 4194304, so 4999999 is no process; 1 (init) is
        // always one; another destination's temporary is not this write's business.
        for name in [
            ".out.txt.tmp-4999999",
            ".out.txt.tmp-1",
            ".other.txt.tmp-4999999",
        ] {
            std::fs::write(dir.join(name), "left behind").unwrap();
        }
        write_atomically(&path, b"new").unwrap();
        let mut names: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        assert_eq!(
            names,
            [".other.txt.tmp-4999999", ".out.txt.tmp-1", "out.txt"]
        );
    }
}
