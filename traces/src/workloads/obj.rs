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
/// number within [`MAX_COORDINATE`] of the origin, a face of fewer than three corners or
/// naming a vertex not given (the loader keeps no line: found afterwards, such a vertex was
/// named by its values alone, and such a face dropped without a word).
struct LineCounter<R> {
    inner: R,
    lines: Lines,
}

/// What [`LineCounter`] knows of the lines handed out so far.
#[derive(Default)]
struct Lines {
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
    /// The last whole line's first bytes (the loader has read a line whole when it
    /// refuses it), to show in the loader's errors.
    previous: Vec<u8>,
    /// Vertex lines so far: a face's negative numbers count back from the last of them.
    vertices: u64,
    /// The first face naming the highest vertex number so far: its line, its text and that
    /// number (the loader finds a vertex past the file's only at an object's end, and names
    /// neither the face nor the vertex).
    furthest: Option<(u64, String, i64)>,
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
        if let Some((_, message)) = &self.lines.refused {
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
                self.lines.byte(byte);
            }
        }
        self.inner.consume(amount);
    }
}

impl Lines {
    /// The next byte handed out.
    fn byte(&mut self, byte: u8) {
        if byte == b'\n' {
            self.newlines += 1;
            self.end_line(self.newlines);
            self.line_bytes = 0;
            std::mem::swap(&mut self.line, &mut self.previous);
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

    /// Line `number` (the current one) is whole: judge it where no line was refused yet
    /// and its bytes were all kept (a longer one is left to the loader: its numbers may run
    /// past them), and count it if it is a vertex.
    fn end_line(&mut self, number: u64) {
        let whole = self.line_bytes <= VERTEX_LINE_BYTES;
        if self.bad_line.is_none() && whole {
            self.bad_line = line_problem(&self.line, self.vertices).map(|why| (number, why));
        }
        let first_word = self
            .line
            .split(u8::is_ascii_whitespace)
            .find(|w| !w.is_empty());
        match first_word {
            Some(b"v") => self.vertices += 1,
            Some(b"f") if whole => self.note_face(number),
            _ => {}
        }
    }

    /// Face line `number` is whole: keep it if it names a higher vertex than any before.
    fn note_face(&mut self, number: u64) {
        let text = String::from_utf8_lossy(&self.line);
        let Some(highest) = face_vertices(&text).max() else {
            return;
        };
        if self
            .furthest
            .as_ref()
            .is_none_or(|&(_, _, most)| highest > most)
        {
            self.furthest = Some((number, text.trim().to_owned(), highest));
        }
    }

    /// The first fault found, with its line where it has one: the line refused first (a
    /// problem line, or an overlong one), else the loader's error `e`.
    fn first_fault(&self, e: &tobj::LoadError) -> (Option<u64>, String) {
        let found = [self.bad_line.clone(), self.refused.clone()];
        if let Some((line, why)) = found.into_iter().flatten().min_by_key(|(line, _)| *line) {
            return (Some(line), why);
        }
        match (e, &self.furthest) {
            (tobj::LoadError::FaceVertexOutOfBounds, Some((line, face, vertex)))
                if *vertex as u64 > self.vertices =>
            {
                let given = counted(self.vertices, "vertex is", "vertices are");
                let why = format!("face `{face}` names vertex {vertex}, where {given} given");
                (Some(*line), why)
            }
            _ => self.loader_error(e),
        }
    }

    /// The loader's error `e` on the line it stopped at, with that line and what such a
    /// line should be.
    fn loader_error(&self, e: &tobj::LoadError) -> (Option<u64>, String) {
        use tobj::LoadError::*;
        if let FaceVertexOutOfBounds
        | FaceTexCoordOutOfBounds
        | FaceNormalOutOfBounds
        | FaceColorOutOfBounds = e
        {
            // Found at an object's end, not on the line read last: no line is named.
            return (
                None,
                format!("{e} (in an object ending at line {})", self.current_line()),
            );
        }
        let line = Some(self.current_line());
        // Read whole, the line is the previous one; cut short (at the end), the current one.
        let text = match self.line_bytes {
            0 => &self.previous,
            _ => &self.line,
        };
        let text = String::from_utf8_lossy(text);
        let expected = match e {
            tobj::LoadError::PositionParseError => {
                "a vertex is `v X Y Z` (W and a colour optional), numbers"
            }
            tobj::LoadError::NormalParseError => "a normal is `vn X Y Z`, numbers",
            tobj::LoadError::TexcoordParseError => {
                "a texture coordinate is `vt U` (V and W optional), numbers"
            }
            tobj::LoadError::FaceParseError => {
                "a face is `f` and three or more corners `V`, `V/T`, `V//N` or `V/T/N`, each a vertex's number (from 1, or from -1 back from the last)"
            }
            _ => return (line, e.to_string()),
        };
        (line, format!("{e} in `{}`: {expected}", text.trim()))
    }
}

/// The vertex numbers a face line's corners name (`V`, `V/T`, `V//N`, `V/T/N`), those that
/// parse.
fn face_vertices(text: &str) -> impl Iterator<Item = i64> + '_ {
    let corners = text.split_whitespace().skip(1);
    corners.filter_map(|corner| corner.split('/').next()?.parse().ok())
}

/// Why the line is refused, when it is a vertex whose position is not a number within
/// [`MAX_COORDINATE`] of the origin, or a face of fewer than three corners, naming vertex 0,
/// or counting back (negative) past the `vertices` before it (any other line, or one whose
/// numbers do not parse, is the loader's to judge; a vertex number past the file's, which
/// may come after the face, is judged at the end: [`Lines::furthest`]).
fn line_problem(line: &[u8], vertices: u64) -> Option<String> {
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
            let corners: Vec<&str> = words.collect();
            if corners.len() < 3 {
                return Some(format!(
                    "face `{}` has {}: a face has three or more",
                    text.trim(),
                    counted(corners.len() as u64, "corner", "corners")
                ));
            }
            let outside =
                |&vertex: &i64| vertex == 0 || (vertex < 0 && vertex.unsigned_abs() > vertices);
            let vertex = face_vertices(text).find(outside)?;
            Some(format!(
                "face `{}` names vertex {vertex}, where {} given before it (a face's vertices count from 1, or from -1 back from the last given)",
                text.trim(),
                counted(vertices, "vertex is", "vertices are"),
            ))
        }
        _ => None,
    }
}

impl Lines {
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
        lines: Lines::default(),
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
    .map_err(|e| match counter.lines.first_fault(&e) {
        (Some(line), message) => error(line, message),
        (None, message) => model_error(message),
    })?;
    let lines = &mut counter.lines;
    if lines.line_bytes > 0 {
        // The last line, without its newline.
        lines.end_line(lines.newlines + 1);
    }
    if let Some((line, why)) = lines.bad_line.take() {
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
        // The loader's errors name the line as written and what such a line should be.
        assert_eq!(
            error("v 0 0 0\nv 1 0 0\nv x 1 0\n"),
            "bad.obj:3: position parse error in `v x 1 0`: a vertex is `v X Y Z` (W and a colour optional), numbers"
        );
        assert_eq!(
            error("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 x 3\n"),
            "bad.obj:4: face parse error in `f 1 x 3`: a face is `f` and three or more corners `V`, `V/T`, `V//N` or `V/T/N`, each a vertex's number (from 1, or from -1 back from the last)"
        );
        // A face naming a vertex past the file's, on its line, with the vertex and the count
        // (the loader had said only "face vertex index out of bounds", at the object's end):
        // the first face naming the highest.
        assert_eq!(
            error("v 0 0 0\nf 1 2 3\nf 1 2 4\nf 1 4 2\nv 1 0 0\n# end\n"),
            "bad.obj:3: face `f 1 2 4` names vertex 4, where 2 vertices are given"
        );
        // Counting back (negative) past the vertices before the face, or naming vertex 0, on
        // the face's line as it is read.
        for (model, line, vertex) in [
            ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/1 2//2 -4\n", 4, "-4"),
            ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\nv 1 1 1\n", 4, "0"),
        ] {
            let said = error(model);
            let expected = format!("bad.obj:{line}: face `");
            assert!(said.starts_with(&expected), "{model:?}: {said}");
            assert!(
                said.contains(&format!("names vertex {vertex}, where")),
                "{said}"
            );
        }
        // Negative numbers count back from the last vertex given (-3 is the first of three),
        // and a face may come before the vertices it names, as the loader takes it.
        assert_eq!(error("v 0 0 0\nv 1 0 0\nv 0 1 0\nf -3 -2 -1\n"), "");
        assert_eq!(error("f 1 2 3\nv 0 0 0\nv 1 0 0\nv 0 1 0\n"), "");
        // An error the loader finds at an object's end is not pinned on the last line read.
        assert_eq!(
            error("v 0 0 0 1 0 0\nv 10 0 0\nv 0 10 0\nf 1 2 3\nv 5 5 5\n# the end\n"),
            "bad.obj: face vertex color index out of bounds (in an object ending at line 6)"
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
        assert_eq!(line_problem(b"v 1e9 -1e9 0", 0), None);
        assert_eq!(
            line_problem(b" v 1e9 -1.1e9 0 ", 0).as_deref(),
            Some("vertex `v 1e9 -1.1e9 0` is not a number within 1e9 of the origin")
        );
        // A face of fewer than three corners is named by its line (the loader had dropped
        // it, and with no other face said only "no faces").
        assert_eq!(
            error("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\nf 1 2 3\n"),
            "bad.obj:4: face `f 1 2` has 2 corners: a face has three or more"
        );
        assert_eq!(
            line_problem(b"f 7", 7).as_deref(),
            Some("face `f 7` has 1 corner: a face has three or more")
        );
        assert_eq!(line_problem(b"f 1/1 2/2 3/3 4/4", 4), None);
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
