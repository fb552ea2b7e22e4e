//! The golden check every machine and level makes: a query's simulated result waits for the
//! golden result the stream carries right after its end, and the two must agree.

use crate::error::SimError;
use occsim_traces::{QueryResult, TileResult};

/// The first field where a simulated result differs from the golden one:
/// (field, simulated value, golden value).
pub(crate) type Difference = Option<(String, String, String)>;

/// Holds the last query's simulated result until its golden result arrives.
#[derive(Default)]
pub(crate) struct GoldenCheck {
    /// The query's number in stream order, and its simulated result.
    awaiting: Option<(usize, QueryResult)>,
    checked: u64,
}

impl GoldenCheck {
    /// Query number `index` (in stream order) ended with `simulated`; check it next.
    pub(crate) fn expect(&mut self, index: usize, simulated: QueryResult) {
        self.awaiting = Some((index, simulated));
    }

    /// The stream's golden result (event number `event`) for the query that just ended,
    /// compared by `difference`.
    pub(crate) fn check(
        &mut self,
        golden: &QueryResult,
        event: u64,
        difference: impl FnOnce(&QueryResult, &QueryResult) -> Difference,
    ) -> Result<(), SimError> {
        let (index, simulated) = self.awaiting.take().ok_or(SimError::ResultWithoutQuery {
            event,
            id: golden.id,
        })?;
        if let Some((field, simulated_value, golden_value)) = difference(&simulated, golden) {
            return Err(SimError::Mismatch {
                id: simulated.id,
                index,
                field,
                simulated: simulated_value,
                golden: golden_value,
            });
        }
        self.checked += 1;
        Ok(())
    }

    /// Queries whose golden result agreed.
    pub(crate) fn checked(&self) -> u64 {
        self.checked
    }
}

/// How two hit lists must agree.
#[derive(Clone, Copy, PartialEq, Eq)]
enum HitOrder {
    /// In the same order (one engine stream in fragment order, as the golden model).
    Same,
    /// As multisets, the simulated list merged from partial lists in another order; on
    /// overflow, which hits a buffer keeps depends on that order, so only their number and
    /// their lying in the tile's box are compared.
    Merged,
}

/// The first field where the simulated result differs from the golden one, whose counters
/// are first saturated to the hardware's width: `(field, simulated, golden)`.
pub fn first_difference(
    simulated: &QueryResult,
    golden: &QueryResult,
    counter_max: u64,
) -> Option<(String, String, String)> {
    difference(simulated, golden, counter_max, HitOrder::Same)
}

/// The first difference between a merged result and the golden one, as [`first_difference`]
/// but with hit lists compared as multisets when no buffer overflowed, and on overflow only
/// by their length and by every kept hit lying in the tile's box (see [`HitOrder::Merged`]).
pub fn merged_difference(
    simulated: &QueryResult,
    golden: &QueryResult,
    counter_max: u64,
) -> Option<(String, String, String)> {
    difference(simulated, golden, counter_max, HitOrder::Merged)
}

fn difference(
    simulated: &QueryResult,
    golden: &QueryResult,
    counter_max: u64,
    order: HitOrder,
) -> Option<(String, String, String)> {
    let differ = |field: String, s: &dyn std::fmt::Debug, g: &dyn std::fmt::Debug| {
        Some((field, format!("{s:?}"), format!("{g:?}")))
    };
    if simulated.id != golden.id {
        return differ("id".into(), &simulated.id, &golden.id);
    }
    if simulated.mode != golden.mode {
        return differ("mode".into(), &simulated.mode, &golden.mode);
    }
    if simulated.tiles.len() != golden.tiles.len() {
        return differ(
            "tile count".into(),
            &simulated.tiles.len(),
            &golden.tiles.len(),
        );
    }
    for (t, (s, g)) in simulated.tiles.iter().zip(&golden.tiles).enumerate() {
        let fields: [(&str, u64, u64); 8] = [
            ("nohc", s.nohc, g.nohc.min(counter_max)),
            ("phc", s.phc, g.phc.min(counter_max)),
            ("xmin", s.xmin as u64, g.xmin as u64),
            ("xmax", s.xmax as u64, g.xmax as u64),
            ("ymin", s.ymin as u64, g.ymin as u64),
            ("ymax", s.ymax as u64, g.ymax as u64),
            ("zmin", s.zmin as u64, g.zmin as u64),
            ("zmax", s.zmax as u64, g.zmax as u64),
        ];
        for (name, sv, gv) in fields {
            if sv != gv {
                return differ(format!("tile {t} {name}"), &sv, &gv);
            }
        }
        if s.hits.len() != g.hits.len() {
            return differ(
                format!("tile {t} hits_written"),
                &s.hits.len(),
                &g.hits.len(),
            );
        }
        if s.overflowed != g.overflowed {
            return differ(format!("tile {t} overflowed"), &s.overflowed, &g.overflowed);
        }
        if let Some(found) = hit_difference(s, g, order) {
            return Some((format!("tile {t} {}", found.0), found.1, found.2));
        }
    }
    if simulated.overflowed_buffers != golden.overflowed_buffers {
        return differ(
            "overflowed_buffers".into(),
            &simulated.overflowed_buffers,
            &golden.overflowed_buffers,
        );
    }
    None
}

/// The first difference between two tiles' hit lists of equal length.
fn hit_difference(
    s: &TileResult,
    g: &TileResult,
    order: HitOrder,
) -> Option<(String, String, String)> {
    let differ = |field: &str, sv: &dyn std::fmt::Debug, gv: &dyn std::fmt::Debug| {
        Some((field.to_owned(), format!("{sv:?}"), format!("{gv:?}")))
    };
    let (sd, gd) = (s.hits.digests(), g.hits.digests());
    match order {
        HitOrder::Same => {
            let (sl, gl) = (s.hits.listed(), g.hits.listed());
            if let Some(h) = (0..sl.len().min(gl.len())).find(|&h| sl[h] != gl[h]) {
                return differ(&format!("hit {h}"), &sl[h], &gl[h]);
            }
            if sl.len() != gl.len() {
                return differ("hits listed", &sl.len(), &gl.len());
            }
            if sd.map(|d| d.in_order) != gd.map(|d| d.in_order) {
                return differ("hits (in-order digest)", &sd, &gd);
            }
        }
        HitOrder::Merged if s.overflowed && g.overflowed => {
            let inside = s.hits.bounds().is_none_or(|b| {
                (s.xmin..=s.xmax).contains(&(b.xmin as u32))
                    && (s.xmin..=s.xmax).contains(&(b.xmax as u32))
                    && (s.ymin..=s.ymax).contains(&(b.ymin as u32))
                    && (s.ymin..=s.ymax).contains(&(b.ymax as u32))
            });
            if !inside {
                return differ("hit outside the box", &s.hits.bounds(), &"none");
            }
        }
        HitOrder::Merged => {
            if s.hits.is_fully_listed() && g.hits.is_fully_listed() {
                let (mut sl, mut gl) = (s.hits.listed().to_vec(), g.hits.listed().to_vec());
                sl.sort_unstable();
                gl.sort_unstable();
                if let Some(h) = (0..sl.len()).find(|&h| sl[h] != gl[h]) {
                    return differ(&format!("hit {h} (sorted)"), &sl[h], &gl[h]);
                }
            }
            if sd.map(|d| d.as_set) != gd.map(|d| d.as_set) {
                return differ("hits (multiset digest)", &sd, &gd);
            }
        }
    }
    None
}
