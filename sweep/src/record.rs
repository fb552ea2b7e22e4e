//! The results files: one JSON line per point (`FILE.jsonl`) and its CSV view (`FILE.csv`).
//!
//! Every line is self-contained: it repeats the sweep's axes and trace digest, so a single
//! line tells which sweep it belongs to, shards can be merged without a header, and a torn
//! last line loses only that line.

use crate::error::{Joining, SweepError};
use crate::grid::{Axis, Grid};
use serde::{Deserialize, Serialize};
use serde_json::Value;
use std::collections::BTreeMap;
use std::io::BufRead;
use std::path::{Path, PathBuf};

type Result<T, E = SweepError> = std::result::Result<T, E>;

/// Format tag written in every line; bump when the schema changes incompatibly.
pub const FORMAT: &str = "occsim-sweep/2";

/// What the caller's evaluator returns for one point.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PointRecord {
    /// The fully resolved architecture the point ran with (every parameter, not just the
    /// swept ones), so a result can be reproduced from its line alone.
    pub resolved_arch: Value,
    /// Metric name -> value (numbers, or any JSON value). Must not hold wall-clock times:
    /// results have to be identical whatever the job count.
    pub metrics: BTreeMap<String, Value>,
}

/// One line of `FILE.jsonl`; the field order here is the byte order on disk.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SweepLine {
    pub format: String,
    /// Index of the point in the full grid (first axis outermost).
    pub point: usize,
    /// Canonical key, e.g. `boards=2,engines=8`.
    pub key: String,
    /// The whole sweep's axes, in command-line order.
    pub axes: Vec<Axis>,
    pub trace_digest: String,
    pub tool_version: String,
    pub resolved_arch: Value,
    pub metrics: BTreeMap<String, Value>,
}

impl SweepLine {
    /// The JSON text of the line, without the newline, ending in the digest of the rest
    /// ([`with_digest`]). Deterministic: struct fields in declaration order, maps sorted by
    /// key, floats in shortest round-trip form.
    pub fn to_json(&self) -> Result<String> {
        let body = serde_json::to_string(self).map_err(SweepError::Encode)?;
        Ok(with_digest(&body))
    }
}

/// The field each line ends in: the FNV-1a 64 digest of the line's text without it.
const DIGEST_FIELD: &str = ",\"digest\":\"";

/// `body` (a JSON object's text) with `"digest":"<16 hex digits>"` added as its last field:
/// the digest of `body` itself, so any edit of the line shows.
pub(crate) fn with_digest(body: &str) -> String {
    let digest = occsim_traces::rng::Fnv1a::of(body.as_bytes());
    let open = body.strip_suffix('}').unwrap_or(body);
    format!("{open}{DIGEST_FIELD}{digest:016x}\"}}")
}

/// The line's text without its digest field if the digest matches it; None if the line has
/// none or it does not match.
fn checked_body(text: &str) -> Option<String> {
    let at = text.rfind(DIGEST_FIELD)?;
    let hex = text[at + DIGEST_FIELD.len()..].strip_suffix("\"}")?;
    let stored = u64::from_str_radix(hex, 16)
        .ok()
        .filter(|_| hex.len() == 16)?;
    let body = format!("{}}}", &text[..at]);
    (occsim_traces::rng::Fnv1a::of(body.as_bytes()) == stored).then_some(body)
}

/// A line read back from a file: the parsed record and its exact text (compared and rewritten
/// byte for byte, never re-encoded).
#[derive(Debug, Clone)]
pub struct StoredLine {
    pub line: SweepLine,
    pub text: String,
    /// Where the line came from, `FILE:LINE`, for messages (empty for fresh lines).
    pub origin: String,
}

impl StoredLine {
    /// Drops what is no longer needed once the line is checked and its text kept: the axes
    /// (equal to the grid's) and the resolved architecture (still in the text). Keeps the
    /// memory held per point near the size of its line.
    pub fn compact(mut self) -> StoredLine {
        self.line.axes = Vec::new();
        self.line.resolved_arch = Value::Null;
        self
    }
}

/// The complete lines of a results file, plus whether an unterminated last line was dropped.
#[derive(Debug)]
pub struct StoredFile {
    pub lines: Vec<StoredLine>,
    pub torn_tail_dropped: bool,
}

/// Whether `bytes`, the unterminated end of a results file, is the start of a result line
/// as [`SweepLine`] serialises, `{"format":"occsim-sweep/...` (or a part of that start;
/// of any version, so that an older file's torn line meets the format check).
fn starts_like_a_result(bytes: &[u8]) -> bool {
    let start = b"{\"format\":\"occsim-sweep/";
    let common = bytes.len().min(start.len());
    bytes[..common] == start[..common]
}

/// Reads `path`. Only newline-terminated lines count: an unterminated last line is what an
/// interrupted append leaves, so it is dropped (and reported). A complete line that does not
/// parse is corruption, reported with file and line number.
pub fn read_results(path: &Path) -> Result<StoredFile> {
    let read_error = |source| SweepError::Read {
        path: path.to_path_buf(),
        source,
    };
    let mut reader = std::io::BufReader::new(std::fs::File::open(path).map_err(read_error)?);
    let mut lines = Vec::new();
    let (mut raw, mut line, mut torn_tail_dropped) = (Vec::new(), 0, false);
    loop {
        raw.clear();
        // Line by line, none past MAX_LINE_BYTES: memory follows the lines kept, not the
        // file (a file of no newlines, /dev/zero, had been read whole).
        let read = std::io::Read::take(&mut reader, MAX_LINE_BYTES + 1)
            .read_until(b'\n', &mut raw)
            .map_err(read_error)?;
        if read == 0 {
            break;
        }
        line += 1;
        if raw.last() != Some(&b'\n') {
            if raw.len() as u64 > MAX_LINE_BYTES {
                return Err(SweepError::LineTooLong {
                    path: path.to_path_buf(),
                    line,
                    max: MAX_LINE_BYTES,
                });
            }
            // The file ends inside it: what an interrupted append leaves, the start of a
            // result line. Anything else is no torn result, and the file no results file
            // (a one-line note without a newline had been dropped and the file replaced).
            if !starts_like_a_result(&raw) {
                return Err(SweepError::NotATornResult {
                    path: path.to_path_buf(),
                    line,
                });
            }
            torn_tail_dropped = true;
            break;
        }
        raw.pop();
        // Blank lines carry nothing.
        if raw.is_empty() {
            continue;
        }
        let text = std::str::from_utf8(&raw)
            .map_err(|_| SweepError::NotUtf8 {
                path: path.to_path_buf(),
                line,
            })?
            .to_string();
        let body = checked_body(&text).ok_or_else(|| SweepError::BadDigest {
            path: path.to_path_buf(),
            line,
        })?;
        let parsed: SweepLine =
            serde_json::from_str(&body).map_err(|source| SweepError::NotAResultLine {
                path: path.to_path_buf(),
                line,
                source,
            })?;
        if parsed.format != FORMAT {
            return Err(SweepError::WrongFormat {
                path: path.to_path_buf(),
                line,
                found: parsed.format,
            });
        }
        lines.push(StoredLine {
            line: parsed,
            text,
            origin: format!("{}:{line}", path.display()),
        });
    }
    Ok(StoredFile {
        lines,
        torn_tail_dropped,
    })
}

/// The longest results line read (a point's line is a few hundred bytes to a few KB).
pub const MAX_LINE_BYTES: u64 = 1 << 20;

/// What a results line must match to belong to a sweep: its grid and trace digest. `joining`
/// (a resume or a merge) shapes the messages.
pub struct Expected<'a> {
    pub grid: &'a Grid,
    pub trace_digest: &'a str,
    pub joining: Joining,
}

/// Checks that a stored line belongs to the expected sweep, was made by this tool version, and
/// carries the key its index gives.
pub fn check_line_belongs(stored: &StoredLine, expected: &Expected<'_>) -> Result<()> {
    let line = &stored.line;
    let at = || stored.origin.clone();
    if line.trace_digest != expected.trace_digest {
        return Err(SweepError::ForeignTrace {
            at: at(),
            found: line.trace_digest.clone(),
            expected: expected.trace_digest.to_owned(),
            joining: expected.joining.clone(),
        });
    }
    if line.axes != expected.grid.axes() {
        return Err(SweepError::ForeignGrid {
            at: at(),
            found: describe_axes(&line.axes),
            expected: describe_axes(expected.grid.axes()),
            joining: expected.joining.clone(),
        });
    }
    if line.tool_version != env!("CARGO_PKG_VERSION") {
        return Err(SweepError::OtherVersion {
            at: at(),
            found: line.tool_version.clone(),
            this: env!("CARGO_PKG_VERSION").to_owned(),
        });
    }
    let expected_key = expected.grid.point(line.point).map(|p| p.key());
    if expected_key.as_deref() != Some(line.key.as_str()) {
        return Err(SweepError::KeyMismatch {
            at: at(),
            point: line.point,
            key: line.key.clone(),
        });
    }
    Ok(())
}

/// `boards=1,2,4 engines=1,2`: axes as the user typed them.
pub fn describe_axes(axes: &[Axis]) -> String {
    let specs: Vec<String> = axes
        .iter()
        .map(|a| format!("{}={}", a.key, a.values.join(",")))
        .collect();
    specs.join(" ")
}

/// `FILE.csv` beside `FILE.jsonl`. A `.csv` output path is refused (it would be overwritten).
pub fn csv_path_for(jsonl: &Path) -> Result<PathBuf> {
    if jsonl.extension().is_some_and(|e| e == "csv") {
        return Err(SweepError::CsvResultsName {
            path: jsonl.to_path_buf(),
        });
    }
    Ok(jsonl.with_extension("csv"))
}

/// The final JSONL: lines sorted by point index, each newline-terminated.
pub fn render_jsonl(lines: &[&StoredLine]) -> String {
    let mut sorted: Vec<&StoredLine> = lines.to_vec();
    sorted.sort_by_key(|s| s.line.point);
    sorted.iter().map(|s| format!("{}\n", s.text)).collect()
}

/// The CSV view: columns `point,key,<axes in order>,<metrics sorted by name>`, rows by point
/// index. A metric missing from a row is an empty cell; strings appear bare, other JSON values
/// as JSON text.
pub fn render_csv(axes: &[Axis], lines: &[&StoredLine]) -> String {
    let metric_names: std::collections::BTreeSet<&str> = lines
        .iter()
        .flat_map(|s| s.line.metrics.keys().map(String::as_str))
        .collect();
    let mut header: Vec<String> = vec!["point".into(), "key".into()];
    header.extend(axes.iter().map(|a| a.key.clone()));
    header.extend(metric_names.iter().map(|m| m.to_string()));
    let mut out = csv_row(&header);
    let mut sorted: Vec<&StoredLine> = lines.to_vec();
    sorted.sort_by_key(|s| s.line.point);
    for stored in sorted {
        let line = &stored.line;
        let mut row = vec![line.point.to_string(), line.key.clone()];
        row.extend(axes.iter().map(|a| axis_value_in_key(&line.key, &a.key)));
        row.extend(metric_names.iter().map(|m| match line.metrics.get(*m) {
            None | Some(Value::Null) => String::new(),
            Some(Value::String(s)) => s.clone(),
            Some(other) => other.to_string(),
        }));
        out.push_str(&csv_row(&row));
    }
    out
}

fn axis_value_in_key(key: &str, axis: &str) -> String {
    key.split(',')
        .filter_map(|pair| pair.split_once('='))
        .find(|(k, _)| *k == axis)
        .map(|(_, v)| v.to_string())
        .unwrap_or_default()
}

/// RFC 4180: quote a field holding a comma, quote or line break; double inner quotes.
fn csv_row(fields: &[String]) -> String {
    let cells: Vec<String> = fields
        .iter()
        .map(|f| {
            if f.contains([',', '"', '\n', '\r']) {
                format!("\"{}\"", f.replace('"', "\"\""))
            } else {
                f.clone()
            }
        })
        .collect();
    format!("{}\n", cells.join(","))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn line(point: usize, key: &str, metrics: &[(&str, Value)]) -> StoredLine {
        let line = SweepLine {
            format: FORMAT.into(),
            point,
            key: key.into(),
            axes: vec![Axis {
                key: "engines".into(),
                values: vec!["1".into(), "2".into()],
            }],
            trace_digest: "d".into(),
            tool_version: env!("CARGO_PKG_VERSION").into(),
            resolved_arch: serde_json::json!({"engines": point + 1}),
            metrics: metrics
                .iter()
                .map(|(k, v)| (k.to_string(), v.clone()))
                .collect(),
        };
        let text = line.to_json().unwrap();
        StoredLine {
            line,
            text,
            origin: String::new(),
        }
    }

    fn read_results_of(path: &Path, line: &str) -> Result<StoredFile> {
        std::fs::write(path, format!("{line}\n")).unwrap();
        read_results(path)
    }

    #[test]
    fn line_schema_is_stable() {
        let l = line(1, "engines=2", &[("total_cycles", Value::from(1.5))]);
        let version = env!("CARGO_PKG_VERSION");
        let body = format!(
            "{{\"format\":\"occsim-sweep/2\",\"point\":1,\"key\":\"engines=2\",\
             \"axes\":[{{\"key\":\"engines\",\"values\":[\"1\",\"2\"]}}],\
             \"trace_digest\":\"d\",\"tool_version\":\"{version}\",\
             \"resolved_arch\":{{\"engines\":2}},\"metrics\":{{\"total_cycles\":1.5}}}}"
        );
        // The digest field closes the line: FNV-1a 64 of everything before it (and the brace).
        let digest = occsim_traces::rng::Fnv1a::of(body.as_bytes());
        let open = &body[..body.len() - 1];
        assert_eq!(l.text, format!("{open},\"digest\":\"{digest:016x}\"}}"));
    }

    #[test]
    fn csv_has_axes_then_sorted_metrics_and_quotes_keys() {
        let a = line(
            1,
            "engines=2",
            &[("z", Value::from(2)), ("a", Value::from("x,y"))],
        );
        let b = line(0, "engines=1", &[("z", Value::from(1.25))]);
        let axes = a.line.axes.clone();
        assert_eq!(
            render_csv(&axes, &[&a, &b]),
            "point,key,engines,a,z\n0,engines=1,1,,1.25\n1,engines=2,2,\"x,y\",2\n"
        );
    }

    #[test]
    fn torn_last_line_is_dropped_and_reported() {
        let temp = crate::test_dir("record-torn");
        let dir = temp.path();
        let path = dir.join("r.jsonl");
        let whole = line(0, "engines=1", &[]).text;
        std::fs::write(&path, format!("{whole}\n{}", &whole[..20])).unwrap();
        let file = read_results(&path).unwrap();
        assert_eq!(file.lines.len(), 1);
        assert!(file.torn_tail_dropped);
    }

    #[test]
    fn corrupt_complete_line_is_an_error_with_file_and_line() {
        let temp = crate::test_dir("record-corrupt");
        let dir = temp.path();
        let path = dir.join("r.jsonl");
        let whole = line(0, "engines=1", &[]).text;
        std::fs::write(&path, format!("{whole}\n{{oops\n")).unwrap();
        let err = read_results(&path).unwrap_err().to_string();
        assert!(
            err.contains("r.jsonl:2: the line's digest does not match"),
            "{err}"
        );
        // A line with a good digest that is no result line is named as such.
        std::fs::write(&path, format!("{whole}\n{}\n", with_digest("{\"oops\":1}"))).unwrap();
        let err = read_results(&path).unwrap_err().to_string();
        assert!(err.contains("r.jsonl:2: not a sweep result line"), "{err}");
    }

    #[test]
    fn an_edited_line_is_caught_by_its_digest() {
        let temp = crate::test_dir("record-edited");
        let path = temp.path().join("r.jsonl");
        let whole = line(0, "engines=1", &[("total_cycles", Value::from(1.5))]).text;
        assert!(read_results_of(&path, &whole).is_ok());
        let edited = whole.replace("1.5", "2.5");
        let err = read_results_of(&path, &edited).unwrap_err().to_string();
        assert!(
            err.contains("r.jsonl:1: the line's digest does not match"),
            "{err}"
        );
    }

    #[test]
    fn csv_output_name_is_refused() {
        assert!(csv_path_for(Path::new("x.csv")).is_err());
        assert_eq!(
            csv_path_for(Path::new("dir/x.jsonl")).unwrap(),
            Path::new("dir/x.csv")
        );
    }
}
