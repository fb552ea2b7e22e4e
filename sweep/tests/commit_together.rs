//! A command's outputs come into place together or not at all ([`commit_together`]).
//!
//! Its own test binary: the last step calls [`remove_temporaries`], as the binary's signal
//! handler does, which marks the whole process as stopping, so no other test may share it.

use occsim_sweep::output::{commit_together, remove_temporaries, write_finished};
use std::path::Path;

/// The names in `dir`, sorted.
fn names_in(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|entry| entry.unwrap().file_name().into_string().unwrap())
        .collect();
    names.sort();
    names
}

#[test]
fn outputs_come_into_place_together_or_not_at_all() {
    let temp = tempfile::tempdir().unwrap();
    let dir = temp.path();

    // Written, nothing is in place yet: each waits beside its path as a hidden temporary.
    let (a, b) = (dir.join("a.jsonl"), dir.join("a.csv"));
    let files = vec![
        write_finished(&a, b"results").unwrap(),
        write_finished(&b, b"view").unwrap(),
    ];
    assert!(!a.exists() && !b.exists());
    assert_eq!(names_in(dir).len(), 2, "{:?}", names_in(dir));
    commit_together(files).unwrap();
    assert_eq!(names_in(dir), ["a.csv", "a.jsonl"]);
    assert_eq!(std::fs::read(&a).unwrap(), b"results");

    // A finished output dropped uncommitted (another output failed) is removed.
    drop(write_finished(&dir.join("dropped.svg"), b"chart").unwrap());
    assert_eq!(names_in(dir), ["a.csv", "a.jsonl"]);

    // A rename that fails (a directory came where the file goes) stops the rest, which are
    // removed; the one before it stays.
    let files = vec![
        write_finished(&dir.join("c.jsonl"), b"results").unwrap(),
        write_finished(&dir.join("taken"), b"view").unwrap(),
        write_finished(&dir.join("c.svg"), b"chart").unwrap(),
    ];
    std::fs::create_dir(dir.join("taken")).unwrap();
    let error = commit_together(files).expect_err("a directory is in the way");
    assert!(error.to_string().contains("taken"), "{error}");
    assert_eq!(names_in(dir), ["a.csv", "a.jsonl", "c.jsonl", "taken"]);

    // Interrupted before the commit (the signal handler removes the temporaries), none
    // comes into place, and the commit says the process is stopping.
    let files = vec![
        write_finished(&dir.join("d.jsonl"), b"results").unwrap(),
        write_finished(&dir.join("d.csv"), b"view").unwrap(),
    ];
    remove_temporaries();
    let error = commit_together(files).expect_err("interrupted");
    assert!(
        format!("{error:?}").contains("the process is stopping"),
        "{error:?}"
    );
    assert_eq!(names_in(dir), ["a.csv", "a.jsonl", "c.jsonl", "taken"]);
}
