//! Camera paths: keyframes of eye and target, spread over the walk's frames or walked at a
//! fixed speed.

use super::WorkloadError;
use glam::Vec3;
use serde::Deserialize;

/// One keyframe: where the eye is and what it looks at (world space, metres).
#[derive(Clone, Copy, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraKeyframe {
    pub eye: [f32; 3],
    pub target: [f32; 3],
}

/// A camera path: a polyline of keyframes.
#[derive(Clone, Debug, PartialEq)]
pub struct CameraPath {
    keyframes: Vec<CameraKeyframe>,
    /// None: the keyframes are spread evenly over the frames (first frame at the first
    /// keyframe, last at the last). Some(step): the eye walks `step` metres per frame along
    /// the polyline from the first keyframe and stops at the last.
    metres_per_frame: Option<f32>,
}

/// The TOML camera file: `metres_per_frame` (optional) and `[[keyframe]]` tables.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CameraFile {
    /// Read as TOML writes it, so that a value no f32 holds is named as written (1e-300
    /// had been refused as `0`, 1e300 as `inf`).
    metres_per_frame: Option<f64>,
    #[serde(default)]
    keyframe: Vec<CameraKeyframe>,
}

/// Largest coordinate accepted, in metres (f32 keeps cameras precise well within it).
const MAX_COORDINATE: f32 = 1e9;

/// Most keyframes a camera file may hold (bounds memory on hostile input).
const MAX_KEYFRAMES: usize = 100_000;

impl CameraPath {
    /// A path through `keyframes`; `source` names them in errors.
    pub fn new(
        keyframes: Vec<CameraKeyframe>,
        metres_per_frame: Option<f32>,
        source: &str,
    ) -> Result<CameraPath, WorkloadError> {
        let fail = |message: String| {
            Err(WorkloadError::Camera {
                file: source.to_owned(),
                message,
            })
        };
        if keyframes.is_empty() {
            return fail(
                "no keyframe: expected at least one `[[keyframe]]` with `eye` and `target`".into(),
            );
        }
        if keyframes.len() > MAX_KEYFRAMES {
            return fail(format!("more than {MAX_KEYFRAMES} keyframes"));
        }
        for (index, k) in keyframes.iter().enumerate() {
            if !k
                .eye
                .iter()
                .chain(&k.target)
                .all(|c| c.abs() <= MAX_COORDINATE)
            {
                return fail(format!(
                    "keyframe {}: coordinates must be numbers within {MAX_COORDINATE:e} metres of the origin",
                    index + 1
                ));
            }
            if k.eye == k.target {
                return fail(format!(
                    "keyframe {}: eye and target are the same point, so there is no view direction",
                    index + 1
                ));
            }
        }
        if let Some(step) = metres_per_frame {
            if !(step.is_finite() && step > 0.0) {
                return fail(format!(
                    "metres_per_frame = {step}: expected a positive distance"
                ));
            }
        }
        Ok(CameraPath {
            keyframes,
            metres_per_frame,
        })
    }

    /// The camera moving in a straight line from `from` to `to`, looking at `target`.
    pub fn line(
        from: [f32; 3],
        to: [f32; 3],
        target: [f32; 3],
    ) -> Result<CameraPath, WorkloadError> {
        let keyframes = vec![
            CameraKeyframe { eye: from, target },
            CameraKeyframe { eye: to, target },
        ];
        CameraPath::new(keyframes, None, "the camera line")
    }

    /// Read a TOML camera file:
    ///
    /// ```toml
    /// metres_per_frame = 1.5          # optional: walk at this speed instead
    /// [[keyframe]]
    /// eye = [0.0, 1.7, 10.0]
    /// target = [0.0, 1.7, 0.0]
    /// ```
    pub fn from_toml(text: &str, file: &str) -> Result<CameraPath, WorkloadError> {
        let fail = |message: String| WorkloadError::Camera {
            file: file.to_owned(),
            message,
        };
        let parsed: CameraFile = toml::from_str(text)
            .map_err(|error| fail(error.to_string().trim_end().replace('\n', " ")))?;
        let step = match parsed.metres_per_frame {
            Some(step) if !(step > 0.0 && step <= MAX_COORDINATE as f64 && step as f32 > 0.0) => {
                let written = match step.abs() {
                    a if a != 0.0 && !(1e-4..1e9).contains(&a) => format!("{step:e}"),
                    _ => step.to_string(),
                };
                return Err(fail(format!(
                    "metres_per_frame = {written}: expected a positive distance, at most {MAX_COORDINATE:e} metres"
                )));
            }
            step => step.map(|step| step as f32),
        };
        CameraPath::new(parsed.keyframe, step, file)
    }

    pub fn keyframes(&self) -> &[CameraKeyframe] {
        &self.keyframes
    }

    /// Eye and target of `frame` out of `frames`.
    pub(crate) fn eye_and_target(&self, frame: u32, frames: u32) -> (Vec3, Vec3) {
        let eyes: Vec<Vec3> = self.keyframes.iter().map(|k| Vec3::from(k.eye)).collect();
        let (segment, t) = match self.metres_per_frame {
            Some(step) => walk_position(&eyes, frame as f32 * step),
            None => {
                let last = (self.keyframes.len() - 1) as f32;
                let u = if frames > 1 {
                    frame as f32 / (frames - 1) as f32
                } else {
                    0.0
                };
                let s = (u * last).min(last);
                let segment = (s.floor() as usize).min(self.keyframes.len().saturating_sub(2));
                (segment, s - segment as f32)
            }
        };
        let a = self.keyframes[segment];
        let b = self.keyframes[(segment + 1).min(self.keyframes.len() - 1)];
        let eye = Vec3::from(a.eye).lerp(Vec3::from(b.eye), t);
        let target = Vec3::from(a.target).lerp(Vec3::from(b.target), t);
        (eye, target)
    }
}

/// The segment and fraction along it `distance` metres down the polyline (clamped to it).
fn walk_position(points: &[Vec3], mut distance: f32) -> (usize, f32) {
    for (segment, pair) in points.windows(2).enumerate() {
        let length = pair[0].distance(pair[1]);
        if distance <= length || segment + 2 == points.len() {
            let t = if length > 0.0 {
                (distance / length).min(1.0)
            } else {
                1.0
            };
            return (segment, t);
        }
        distance -= length;
    }
    (0, 0.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keyframes_spread_over_the_frames() {
        let path = CameraPath::line([0.0, 0.0, 0.0], [10.0, 0.0, 0.0], [0.0, 0.0, -5.0]).unwrap();
        assert_eq!(path.eye_and_target(0, 3).0, Vec3::ZERO);
        assert_eq!(path.eye_and_target(1, 3).0, Vec3::new(5.0, 0.0, 0.0));
        assert_eq!(path.eye_and_target(2, 3).0, Vec3::new(10.0, 0.0, 0.0));
        assert_eq!(path.eye_and_target(0, 1).0, Vec3::ZERO);
    }

    #[test]
    fn walking_stops_at_the_last_keyframe() {
        let text = "metres_per_frame = 4.0\n[[keyframe]]\neye = [0, 0, 0]\ntarget = [0, 0, -1]\n[[keyframe]]\neye = [0, 0, -6]\ntarget = [0, 0, -7]\n[[keyframe]]\neye = [6, 0, -6]\ntarget = [7, 0, -6]\n";
        let path = CameraPath::from_toml(text, "walk.toml").unwrap();
        assert_eq!(path.eye_and_target(1, 10).0, Vec3::new(0.0, 0.0, -4.0));
        assert_eq!(path.eye_and_target(2, 10).0, Vec3::new(2.0, 0.0, -6.0));
        assert_eq!(path.eye_and_target(9, 10).0, Vec3::new(6.0, 0.0, -6.0));
    }

    #[test]
    fn malformed_camera_files_are_refused_clearly() {
        let error = |text: &str| {
            CameraPath::from_toml(text, "cam.toml")
                .unwrap_err()
                .to_string()
        };
        let syntax = error("[[keyframe]]\neye = [0, 0\n");
        assert!(syntax.starts_with("cam.toml: "), "{syntax}");
        assert!(syntax.contains("line 2"), "{syntax}");
        assert!(error("").contains("no keyframe"));
        assert!(error("[[keyframe]]\neye = [0, 0, 0]\n").contains("target"));
        assert!(error("[[keyframe]]\neye = [0, 0, 0]\ntarget = [0, 0, 0]\n").contains("same point"));
        assert!(error("[[keyframe]]\neye = [0, 0, nan]\ntarget = [0, 0, 1]\n").contains("within"));
        assert!(error("[[keyframe]]\neye = [0, 0, 1e30]\ntarget = [0, 0, 1]\n").contains("within"));
        assert!(
            error("[[keyframe]]\neye = [0, 0, 0]\ntarget = [0, 0, 1]\nfov = 3\n").contains("fov")
        );
        // A step no f32 holds is named as written (it had been `0` and `inf`).
        for (step, named) in [("-1", "-1"), ("1e-300", "1e-300"), ("1e300", "1e300")] {
            let text = format!(
                "metres_per_frame = {step}\n[[keyframe]]\neye = [0, 0, 0]\ntarget = [0, 0, 1]\n"
            );
            assert_eq!(
                error(&text),
                format!("cam.toml: metres_per_frame = {named}: expected a positive distance, at most 1e9 metres")
            );
        }
    }
}
