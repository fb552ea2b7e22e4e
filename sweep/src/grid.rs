//! The sweep grid: `key=v1,v2,...` axes, their cartesian product, and shards `K/N`.
//!
//! Architecture invariant: a point's index and key depend only on the axes as given (their
//! order and their values' order), never on jobs, shards or timing.

use crate::error::SweepError;

type Result<T, E = SweepError> = std::result::Result<T, E>;

/// Largest grid we agree to enumerate, in points; guards against typos like `engines=1,...`
/// repeated over many axes allocating without bound.
pub const MAX_GRID_POINTS: usize = 1_000_000;

/// Caller-supplied check of one `key=value` pair (the machine configuration knows which keys
/// exist and which values are legal). Returns a message for the user on rejection.
/// Checks one `key=value` of an axis: the value as the parameter reads it (`4` for `04`,
/// `100.0` for `1e2`), so that one value written twice two ways is found, or why it is
/// refused.
pub type AxisValidator<'a> = &'a dyn Fn(&str, &str) -> std::result::Result<String, String>;

/// One swept parameter: its key and the values to try, in the order given.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Axis {
    pub key: String,
    pub values: Vec<String>,
}

/// The ordered list of axes; its points are their cartesian product, first axis outermost.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Grid {
    axes: Vec<Axis>,
    point_count: usize,
}

/// One point of the grid: its stable index (position in the full product) and one value per
/// axis, in axis order.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Point {
    pub index: usize,
    pub values: Vec<(String, String)>,
}

impl Point {
    /// The canonical key, e.g. `boards=2,engines=8` (axis order; empty for a grid without axes).
    pub fn key(&self) -> String {
        let pairs: Vec<String> = self
            .values
            .iter()
            .map(|(k, v)| format!("{k}={v}"))
            .collect();
        pairs.join(",")
    }

    /// The value this point gives to axis `key`, if that key is swept.
    #[cfg(test)]
    pub fn get(&self, key: &str) -> Option<&str> {
        self.values
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }
}

/// A shard `K/N`: this run evaluates the points whose index % N == K - 1.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Shard {
    /// 1-based shard number K, 1 <= K <= count.
    pub number: usize,
    /// Number of shards N >= 1.
    pub count: usize,
}

impl Shard {
    /// Parses `K/N` (1-based K), e.g. `2/8`, as used by a Slurm array (`$SLURM_ARRAY_TASK_ID/8`).
    pub fn parse(spec: &str) -> Result<Shard> {
        let bad = |why: String, source| SweepError::BadShard {
            spec: spec.to_owned(),
            why,
            source,
        };
        let (k, n) = spec
            .split_once('/')
            .ok_or_else(|| bad("expected K/N, e.g. 1/4".to_owned(), None))?;
        let whole = |part: &str, name: &str| {
            part.trim()
                .parse::<usize>()
                .map_err(|e| bad(format!("{name} '{part}' is not a whole number"), Some(e)))
        };
        let (number, count) = (whole(k, "K")?, whole(n, "N")?);
        if count == 0 {
            return Err(bad("N must be at least 1".to_owned(), None));
        }
        if number == 0 || number > count {
            return Err(bad(
                format!("K must be between 1 and N={count} (K is 1-based)"),
                None,
            ));
        }
        Ok(Shard { number, count })
    }

    pub fn contains(&self, index: usize) -> bool {
        index % self.count == self.number - 1
    }
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.number, self.count)
    }
}

fn bad_axis(spec: &str, why: String) -> SweepError {
    SweepError::BadAxis {
        spec: spec.to_owned(),
        why,
    }
}

/// Keys may contain letters, digits, `_`, `-` and `.` (for nested keys like `memory.cas`).
fn check_key(key: &str, spec: &str) -> Result<()> {
    if key.is_empty() {
        return Err(bad_axis(
            spec,
            "missing key before '=' (expected key=v1,v2,...)".to_owned(),
        ));
    }
    if let Some(c) = key
        .chars()
        .find(|c| !(c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.')))
    {
        return Err(bad_axis(
            spec,
            format!("key '{key}' contains '{c}'; keys use letters, digits, '_', '-', '.'"),
        ));
    }
    Ok(())
}

/// Values must keep the canonical key unambiguous: no `,` `=` `"`, whitespace or control codes.
fn check_value(value: &str, key: &str, spec: &str) -> Result<()> {
    if value.is_empty() {
        return Err(bad_axis(
            spec,
            format!("empty value in the list for '{key}'"),
        ));
    }
    if let Some(c) = value
        .chars()
        .find(|c| c.is_whitespace() || c.is_control() || matches!(c, '=' | '"'))
    {
        return Err(bad_axis(
            spec,
            format!("value '{value}' for '{key}' contains {c:?}, which is not allowed"),
        ));
    }
    Ok(())
}

/// Parses one `key=v1,v2,...` into an axis (structure only; see [`Grid::parse`]).
pub fn parse_axis(spec: &str) -> Result<Axis> {
    let (key, list) = spec
        .split_once('=')
        .ok_or_else(|| bad_axis(spec, "expected key=v1,v2,... (no '=' found)".to_owned()))?;
    let key = key.trim();
    check_key(key, spec)?;
    if list.trim().is_empty() {
        return Err(bad_axis(spec, format!("no values after '{key}='")));
    }
    let mut values: Vec<String> = Vec::new();
    for value in list.split(',').map(str::trim) {
        check_value(value, key, spec)?;
        if values.iter().any(|v| v == value) {
            return Err(bad_axis(
                spec,
                format!("value '{value}' appears twice for '{key}'"),
            ));
        }
        values.push(value.to_string());
    }
    Ok(Axis {
        key: key.to_string(),
        values,
    })
}

impl Grid {
    /// Parses axis specs `key=v1,v2,...`, in order, and asks `validate` about every key=value.
    pub fn parse(specs: &[String], validate: AxisValidator<'_>) -> Result<Grid> {
        let axes = specs
            .iter()
            .map(|spec| parse_axis(spec))
            .collect::<Result<Vec<_>>>()?;
        for axis in &axes {
            let mut read: Vec<(String, &str)> = Vec::new();
            for value in &axis.values {
                let as_read =
                    validate(&axis.key, value).map_err(|why| SweepError::RejectedValue {
                        key: axis.key.clone(),
                        value: value.clone(),
                        why,
                    })?;
                // One point run twice under two names (`engines=4,04`, `clock_mhz=1e2,100`).
                if let Some((_, first)) = read.iter().find(|(seen, _)| *seen == as_read) {
                    return Err(SweepError::RejectedValue {
                        key: axis.key.clone(),
                        value: value.clone(),
                        why: format!("the same value as '{first}' ({as_read}) given before it"),
                    });
                }
                read.push((as_read, value));
            }
        }
        Grid::from_axes(axes)
    }

    /// Builds a grid from already parsed axes (e.g. read back from a results file), checking
    /// the structural rules again: unique keys, legal keys and values, bounded size.
    pub fn from_axes(axes: Vec<Axis>) -> Result<Grid> {
        let mut point_count: usize = 1;
        for (i, axis) in axes.iter().enumerate() {
            let spec = format!("{}={}", axis.key, axis.values.join(","));
            check_key(&axis.key, &spec)?;
            if axis.values.is_empty() {
                return Err(bad_axis(&spec, format!("no values after '{}='", axis.key)));
            }
            for (j, value) in axis.values.iter().enumerate() {
                check_value(value, &axis.key, &spec)?;
                if axis.values[..j].contains(value) {
                    return Err(bad_axis(
                        &spec,
                        format!("value '{value}' appears twice for '{}'", axis.key),
                    ));
                }
            }
            if axes[..i].iter().any(|a| a.key == axis.key) {
                return Err(SweepError::DuplicateAxis {
                    key: axis.key.clone(),
                });
            }
            point_count = point_count
                .checked_mul(axis.values.len())
                .filter(|&n| n <= MAX_GRID_POINTS)
                .ok_or(SweepError::TooManyPoints {
                    limit: MAX_GRID_POINTS,
                })?;
        }
        Ok(Grid { axes, point_count })
    }

    pub fn axes(&self) -> &[Axis] {
        &self.axes
    }

    /// Number of points in the full product (1 for a grid without axes).
    #[expect(
        clippy::len_without_is_empty,
        reason = "a grid always has a point: one without axes has the empty one"
    )]
    pub fn len(&self) -> usize {
        self.point_count
    }

    /// The point at `index` of the full product, or None past the end. Mixed radix, the last
    /// axis varying fastest.
    pub fn point(&self, index: usize) -> Option<Point> {
        if index >= self.point_count {
            return None;
        }
        let mut rest = index;
        let mut values = vec![(String::new(), String::new()); self.axes.len()];
        for (slot, axis) in values.iter_mut().zip(&self.axes).rev() {
            let n = axis.values.len();
            *slot = (axis.key.clone(), axis.values[rest % n].clone());
            rest /= n;
        }
        Some(Point { index, values })
    }

    /// The indices a shard runs (all points when `shard` is None), ascending.
    pub fn selected_indices(&self, shard: Option<Shard>) -> Vec<usize> {
        (0..self.point_count)
            .filter(|&i| shard.is_none_or(|s| s.contains(i)))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn accept_all(_: &str, value: &str) -> std::result::Result<String, String> {
        Ok(value.to_owned())
    }

    fn grid(specs: &[&str]) -> Result<Grid> {
        let specs: Vec<String> = specs.iter().map(|s| s.to_string()).collect();
        Grid::parse(&specs, &accept_all)
    }

    fn error_of(specs: &[&str]) -> String {
        grid(specs).unwrap_err().to_string()
    }

    #[test]
    fn product_has_first_axis_outermost_and_canonical_keys() {
        let g = grid(&["boards=1,2", "engines=1,4,16"]).unwrap();
        assert_eq!(g.len(), 6);
        let keys: Vec<String> = (0..6).map(|i| g.point(i).unwrap().key()).collect();
        assert_eq!(
            keys,
            [
                "boards=1,engines=1",
                "boards=1,engines=4",
                "boards=1,engines=16",
                "boards=2,engines=1",
                "boards=2,engines=4",
                "boards=2,engines=16",
            ]
        );
        assert!(g.point(6).is_none());
        assert_eq!(g.point(4).unwrap().get("engines"), Some("4"));
    }

    #[test]
    fn grid_without_axes_has_one_point_with_empty_key() {
        let g = grid(&[]).unwrap();
        assert_eq!(g.len(), 1);
        assert_eq!(g.point(0).unwrap().key(), "");
    }

    #[test]
    fn whitespace_around_values_is_trimmed() {
        let g = grid(&["engines= 1, 2"]).unwrap();
        assert_eq!(g.axes()[0].values, ["1", "2"]);
    }

    #[test]
    fn malformed_set_specs_are_rejected_clearly() {
        assert!(error_of(&["boards"]).contains("expected key=v1,v2"));
        assert!(error_of(&["=1,2"]).contains("missing key"));
        assert!(error_of(&["boards="]).contains("no values after 'boards='"));
        assert!(error_of(&["boards=1,,2"]).contains("empty value"));
        assert!(error_of(&["boards=1,2,1"]).contains("'1' appears twice"));
        assert!(error_of(&["bo ards=1"]).contains("contains ' '"));
        assert!(error_of(&["boards=1=2"]).contains("not allowed"));
        assert!(
            error_of(&["boards=1", "engines=2", "boards=4"]).contains("'boards' is given twice")
        );
    }

    #[test]
    fn validator_rejections_name_the_key_and_value() {
        let specs = vec!["boards=1,3".to_string()];
        let only_powers_of_two = |key: &str, value: &str| -> std::result::Result<String, String> {
            match (key, value) {
                ("boards", "1" | "2" | "4") => Ok(value.to_owned()),
                ("boards", _) => Err("boards must be 1, 2 or 4".to_string()),
                _ => Err(format!("unknown key '{key}'")),
            }
        };
        let err = Grid::parse(&specs, &only_powers_of_two)
            .unwrap_err()
            .to_string();
        assert_eq!(err, "bad axis value boards=3: boards must be 1, 2 or 4");
    }

    #[test]
    fn oversized_grids_are_rejected() {
        let thousand = (0..1000)
            .map(|i| i.to_string())
            .collect::<Vec<_>>()
            .join(",");
        let specs = [
            format!("a={thousand}"),
            format!("b={thousand}"),
            "c=1,2".to_string(),
        ];
        let specs: Vec<&str> = specs.iter().map(String::as_str).collect();
        assert!(error_of(&specs).contains("more than 1000000 points"));
    }

    #[test]
    fn shard_parsing_and_selection() {
        let s = Shard::parse("2/3").unwrap();
        let g = grid(&["a=0,1,2,3,4,5,6"]).unwrap();
        assert_eq!(g.selected_indices(Some(s)), [1, 4]);
        assert_eq!(g.selected_indices(None), [0, 1, 2, 3, 4, 5, 6]);
        assert_eq!(s.to_string(), "2/3");
    }

    #[test]
    fn bad_shard_specs_are_rejected_clearly() {
        let err = |spec: &str| Shard::parse(spec).unwrap_err().to_string();
        assert!(err("3").contains("expected K/N"));
        assert!(err("0/3").contains("K must be between 1 and N=3"));
        assert!(err("4/3").contains("K must be between 1 and N=3"));
        assert!(err("1/0").contains("N must be at least 1"));
        assert!(err("a/3").contains("'a' is not a whole number"));
        assert!(err("1/-2").contains("'-2' is not a whole number"));
    }
}
