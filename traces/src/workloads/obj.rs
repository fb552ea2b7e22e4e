//! Wavefront OBJ import (through `tobj`): anyone's own model as a workload. Each OBJ object
//! or group becomes objects of at most `max_triangles_per_object` triangles (larger ones are
//! split at the median along their longest axis), so the hierarchy has something to cull.

use super::camera::{CameraKeyframe, CameraPath};
use super::{SceneObject, WorkloadError, WorkloadScene};
use crate::geometry::Aabb;
use crate::words::counted;
use glam::Vec3;
use std::io::{BufRead, Read};

/// How an OBJ file becomes a scene.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ObjOptions {
    /// Largest object, in triangles, before it is split.
    pub max_triangles_per_object: u32,
}

impl Default for ObjOptions {
    fn default() -> ObjOptions {
        ObjOptions {
            max_triangles_per_object: 512,
        }
    }
}

/// Largest coordinate accepted, in model units: far beyond any real model, and small enough
/// that cameras and boxes keep f32 precision without overflow.
const MAX_COORDINATE: f32 = 1e9;

/// Longest OBJ line accepted, in bytes (bounds memory on hostile input).
const MAX_LINE_BYTES: usize = 1 << 20;

/// Bytes of a line kept to check it as a vertex or a face: far more than three numbers take.
const VERTEX_LINE_BYTES: usize = 256;

/// Counts the lines a reader has handed out, refuses overlong lines, and finds the first
/// line the model's checks would refuse without its line: a vertex whose position is not a
/// number within [`MAX_COORDINATE`] of the origin, a face of fewer than three corners (the
/// loader keeps no line: found afterwards, such a vertex was named by its values alone, and
/// such a face dropped without a word).
struct LineCounter<R> {
    inner: R,
    /// Newlines consumed so far.
    newlines: u64,
    /// Bytes consumed since the last newline.
    line_bytes: usize,
    /// The line we refused and why, once a line grew too long.
    refused: Option<(u64, String)>,
    /// The current line's first bytes, as far as [`VERTEX_LINE_BYTES`].
    line: Vec<u8>,
    /// The first line refused ([`line_problem`]): its number and why.
    bad_line: Option<(u64, String)>,
}

impl<R: BufRead> Read for LineCounter<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let available = self.fill_buf()?;
        let n = available.len().min(buf.len());
        buf[..n].copy_from_slice(&available[..n]);
        self.consume(n);
        Ok(n)
    }
}

impl<R: BufRead> BufRead for LineCounter<R> {
    fn fill_buf(&mut self) -> std::io::Result<&[u8]> {
        if let Some((_, message)) = &self.refused {
            return Err(std::io::Error::new(
                std::io::ErrorKind::InvalidData,
                message.clone(),
            ));
        }
        self.inner.fill_buf()
    }

    fn consume(&mut self, amount: usize) {
        // The bytes are still buffered: look at them before letting them go.
        if let Ok(buffer) = self.inner.fill_buf() {
            for &byte in &buffer[..amount.min(buffer.len())] {
                if byte == b'\n' {
                    self.newlines += 1;
                    // A line longer than the bytes kept is left to the model's check
                    // (its numbers may run past them).
                    if self.bad_line.is_none() && self.line_bytes <= VERTEX_LINE_BYTES {
                        self.bad_line = line_problem(&self.line).map(|why| (self.newlines, why));
                    }
                    self.line_bytes = 0;
                    self.line.clear();
                } else {
                    if self.line.len() < VERTEX_LINE_BYTES {
                        self.line.push(byte);
                    }
                    self.line_bytes += 1;
                    if self.line_bytes > MAX_LINE_BYTES && self.refused.is_none() {
                        let message = format!("line longer than {MAX_LINE_BYTES} bytes");
                        self.refused = Some((self.newlines + 1, message));
                    }
                }
            }
        }
        self.inner.consume(amount);
    }
}

/// Why the line is refused, when it is a vertex whose position is not a number within
/// [`MAX_COORDINATE`] of the origin or a face of fewer than three corners (any other line,
/// or one whose numbers do not parse, is the loader's to judge).
fn line_problem(line: &[u8]) -> Option<String> {
    let text = std::str::from_utf8(line).ok()?;
    let mut words = text.split_whitespace();
    match words.next() {
        Some("v") => {
            let numbers: Vec<f32> = words.take(3).map_while(|w| w.parse().ok()).collect();
            (numbers.len() == 3 && !numbers.iter().all(|v| v.abs() <= MAX_COORDINATE)).then(|| {
                format!(
                    "vertex `{}` is not a number within {MAX_COORDINATE:e} of the origin",
                    text.trim()
                )
            })
        }
        Some("f") => {
            let corners = words.count();
            (corners < 3).then(|| {
                format!(
                    "face `{}` has {}: a face has three or more",
                    text.trim(),
                    counted(corners as u64, "corner", "corners")
                )
            })
        }
        _ => None,
    }
}

impl<R> LineCounter<R> {
    /// The line being read when parsing stopped (1-based).
    fn current_line(&self) -> u64 {
        if self.line_bytes > 0 {
            self.newlines + 1
        } else {
            self.newlines.max(1)
        }
    }
}

/// Load an OBJ model from `reader`; `file` names it in errors and reports. Faces are
/// triangulated; points, lines and materials are ignored. The default camera circles the
/// model, looking at its centre.
pub fn load_obj(
    reader: impl BufRead,
    file: &str,
    options: &ObjOptions,
) -> Result<WorkloadScene, WorkloadError> {
    let error = |line: u64, message: String| WorkloadError::Obj {
        file: file.to_owned(),
        line,
        message,
    };
    let model_error = |message: String| WorkloadError::ObjModel {
        file: file.to_owned(),
        message,
    };
    let mut counter = LineCounter {
        inner: reader,
        newlines: 0,
        line_bytes: 0,
        refused: None,
        line: Vec::new(),
        bad_line: None,
    };
    let load_options = tobj::LoadOptions {
        triangulate: true,
        ignore_points: true,
        ignore_lines: true,
        ..Default::default()
    };
    let (models, _materials) = tobj::load_obj_buf(&mut counter, &load_options, |_| {
        Err(tobj::LoadError::OpenFileFailed)
    })
    .map_err(|e| {
        let (line, message) = counter
            .refused
            .clone()
            .unwrap_or_else(|| (counter.current_line(), format!("{e}")));
        error(line, message)
    })?;
    if counter.bad_line.is_none() && counter.line_bytes <= VERTEX_LINE_BYTES {
        // The last line, without its newline.
        let last = counter.newlines + 1;
        counter.bad_line = line_problem(&counter.line).map(|why| (last, why));
    }
    if let Some((line, why)) = counter.bad_line {
        return Err(error(line, why));
    }
    let limit = options.max_triangles_per_object.max(1) as usize;
    let mut objects = Vec::new();
    for model in &models {
        let positions = &model.mesh.positions;
        let vertex = |index: u32| -> Option<Vec3> {
            let i = index as usize * 3;
            let p = Vec3::new(
                *positions.get(i)?,
                *positions.get(i + 1)?,
                *positions.get(i + 2)?,
            );
            (p.is_finite() && p.abs().max_element() <= MAX_COORDINATE).then_some(p)
        };
        let mut triangles = Vec::with_capacity(model.mesh.indices.len() / 3);
        for face in model.mesh.indices.chunks_exact(3) {
            let corners = [vertex(face[0]), vertex(face[1]), vertex(face[2])];
            let [Some(a), Some(b), Some(c)] = corners else {
                // A vertex line too long to have been checked as it was read (past
                // `VERTEX_LINE_BYTES`): the loader keeps no line of a vertex, its values
                // name it.
                let bad = face
                    .iter()
                    .zip(corners)
                    .find_map(|(&index, corner)| corner.is_none().then_some(index as usize * 3));
                let values = bad.map_or(String::new(), |i| {
                    let value = |k: usize| match positions.get(i + k) {
                        Some(v) if v.abs() >= 1e6 => format!("{v:e}"),
                        Some(v) => v.to_string(),
                        None => "?".into(),
                    };
                    format!(" (v {} {} {})", value(0), value(1), value(2))
                });
                return Err(model_error(format!(
                    "object `{}` has a vertex{values} that is not a number within {MAX_COORDINATE:e} of the origin",
                    model.name
                )));
            };
            triangles.push([a, b, c]);
        }
        split_into_objects(triangles, limit, &mut objects);
    }
    let no_faces =
        "no faces: the model has no triangles to draw (a face has three corners or more)";
    let Some(bounds) = objects.iter().map(|o| o.bounds).reduce(Aabb::union) else {
        return Err(model_error(no_faces.into()));
    };
    let Some(camera) = orbit(&bounds) else {
        return Err(model_error(
            "the model is too small for its distance from the origin to be seen".into(),
        ));
    };
    WorkloadScene::new(file, objects, camera).ok_or_else(|| model_error(no_faces.into()))
}

/// Split `triangles` at the median centre along the longest axis until each part holds at
/// most `limit`, appending the parts as objects.
fn split_into_objects(mut triangles: Vec<[Vec3; 3]>, limit: usize, objects: &mut Vec<SceneObject>) {
    if triangles.len() <= limit {
        objects.extend(SceneObject::new(triangles));
        return;
    }
    let centre = |t: &[Vec3; 3]| (t[0] + t[1] + t[2]) / 3.0;
    let Some(bounds) = Aabb::around(triangles.iter().map(centre)) else {
        return;
    };
    let extent = bounds.max - bounds.min;
    let axis = extent.max_position();
    triangles.sort_by(|a, b| centre(a)[axis].total_cmp(&centre(b)[axis]));
    let upper = triangles.split_off(triangles.len() / 2);
    split_into_objects(triangles, limit, objects);
    split_into_objects(upper, limit, objects);
}

/// Eight keyframes circling the model at 1.2 diagonals, a little above it (None when f32
/// cannot tell the eye from the centre).
fn orbit(bounds: &Aabb) -> Option<CameraPath> {
    let centre = bounds.centre();
    let radius = (bounds.max - bounds.min).length().max(1e-3) * 1.2;
    let keyframes = (0..=8)
        .map(|k| {
            let angle = std::f32::consts::TAU * k as f32 / 8.0;
            let eye = centre
                + Vec3::new(
                    libm::sinf(angle) * radius,
                    radius * 0.3,
                    libm::cosf(angle) * radius,
                );
            CameraKeyframe {
                eye: eye.to_array(),
                target: centre.to_array(),
            }
        })
        .collect();
    CameraPath::new(keyframes, None, "orbit").ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    const TETRAHEDRON: &str =
        "# a tetrahedron\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n";

    #[test]
    fn loads_and_splits_a_model() {
        let scene = load_obj(TETRAHEDRON.as_bytes(), "tet.obj", &ObjOptions::default()).unwrap();
        assert_eq!(scene.triangle_count(), 4);
        assert_eq!(scene.object_count(), 1);
        let split = load_obj(
            TETRAHEDRON.as_bytes(),
            "tet.obj",
            &ObjOptions {
                max_triangles_per_object: 1,
            },
        )
        .unwrap();
        assert_eq!(split.object_triangle_counts(), vec![1, 1, 1, 1]);
    }

    #[test]
    fn bad_models_name_file_and_line() {
        let error = |text: &str| {
            load_obj(text.as_bytes(), "bad.obj", &ObjOptions::default())
                .err()
                .map(|e| e.to_string())
                .unwrap_or_default()
        };
        assert_eq!(
            error("v 0 0 0\nv 1 0 0\nv x 1 0\n"),
            "bad.obj:3: position parse error"
        );
        assert!(
            error("v 0 0 0\nf 1 2 3\n").starts_with("bad.obj:2: "),
            "{}",
            error("v 0 0 0\nf 1 2 3\n")
        );
        assert_eq!(
            error("# nothing\n"),
            "bad.obj: no faces: the model has no triangles to draw (a face has three corners or more)"
        );
        // A vertex that is not a number, or is one beyond 1e9, is named by its line as it
        // is written, used by a face or not, the last line too.
        assert_eq!(
            error("o a\nv 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n"),
            "bad.obj:4: vertex `v nan 1 0` is not a number within 1e9 of the origin"
        );
        assert_eq!(
            error("v 1e30 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"),
            "bad.obj:1: vertex `v 1e30 0 0` is not a number within 1e9 of the origin"
        );
        assert_eq!(
            error("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nv\t0 inf 0"),
            "bad.obj:5: vertex `v\t0 inf 0` is not a number within 1e9 of the origin"
        );
        // A vertex of four numbers (w) or with a colour is checked on its position alone;
        // 1e9 itself is in range.
        for model in [
            "v 0 0 0 1\nv 1 0 0 1\nv 0 1 0 1e30\nf 1 2 3\n",
            "v 0 0 0 0.5 0.5 0.5\nv 1 0 0 0.5 0.5 0.5\nv 0 1 0 0.5 0.5 nan\nf 1 2 3\n",
        ] {
            assert_eq!(error(model), "", "{model}");
        }
        // A vertex line longer than the bytes kept is not judged on its first ones (this
        // one's third number is 1.0, written with 250 zeros).
        let long_one = format!("1{}e-250", "0".repeat(250));
        let model = format!("v 0 0 0\nv 1 0 0\nv 0 0 {long_one}\nf 1 2 3\n");
        assert_eq!(error(&model), "");
        assert_eq!(line_problem(b"v 1e9 -1e9 0"), None);
        assert_eq!(
            line_problem(b" v 1e9 -1.1e9 0 ").as_deref(),
            Some("vertex `v 1e9 -1.1e9 0` is not a number within 1e9 of the origin")
        );
        // A face of fewer than three corners is named by its line (the loader had dropped
        // it, and with no other face said only "no faces").
        assert_eq!(
            error("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\nf 1 2 3\n"),
            "bad.obj:4: face `f 1 2` has 2 corners: a face has three or more"
        );
        assert_eq!(
            line_problem(b"f 7").as_deref(),
            Some("face `f 7` has 1 corner: a face has three or more")
        );
        assert_eq!(line_problem(b"f 1/1 2/2 3/3 4/4"), None);
        let tiny_and_far = "v 9e8 9e8 9e8\nv 9e8 9e8 9e8\nv 9e8 9e8 9e8\nf 1 2 3\n";
        assert!(
            error(tiny_and_far).contains("too small"),
            "{}",
            error(tiny_and_far)
        );
        let long = format!("v 0 0 0\n# {}\n", "x".repeat(MAX_LINE_BYTES + 10));
        assert_eq!(
            error(&long),
            format!("bad.obj:2: line longer than {MAX_LINE_BYTES} bytes")
        );
    }
}
