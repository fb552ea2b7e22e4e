//! A verbose buffer's hit list, held in memory that does not grow with the hits.
//!
//! A verbose query's tiles can hold millions of hits each (a buffer may be 16 Mi entries and
//! a query 65,536 tiles), far more than a simulator should keep. What every comparison needs
//! is kept exactly in constant space: how many hits the buffer holds, a digest of them in
//! order, a digest of them as a multiset (partial lists merged from several Image Engines
//! come in another order), their bounding box and the last hit (the -1 terminator may yet
//! overwrite it). Only the first hits are also listed, up to a cap the query sets
//! ([`listed_hits_per_tile`]), so a small query prints its hits and a huge one stays small.
//!
//! The in-order digest is a polynomial hash, `D(h_1..h_n) = sum mix(h_i) * B^(n-i)` modulo
//! 2^64 with `B` odd, so appending a list is `D(a) * B^len(b) + D(b)` and dropping the last
//! hit is `(D - mix(last)) * B^-1`. The multiset digest is `sum mix(h_i)`. A merge that cuts
//! a list short anywhere but at its end makes both unknown (which hits it keeps depends on
//! the merge order); the count, the box and the listed prefix stay exact.

use serde::{Deserialize, Serialize};

/// One hit: the window position of a fragment that passed.
pub type Hit = (u16, u16);

/// Most hits one query lists over all its tiles (the rest are counted and digested only).
pub const LISTED_HITS_PER_QUERY: usize = 1 << 16;

/// The hits a query of `tiles` tiles lists per tile: its share of [`LISTED_HITS_PER_QUERY`].
pub fn listed_hits_per_tile(tiles: usize) -> usize {
    LISTED_HITS_PER_QUERY / tiles.max(1)
}

/// The polynomial digest's base: odd, so it has an inverse modulo 2^64.
const BASE: u64 = 0x9E37_79B9_7F4A_7C15;
/// `BASE`'s inverse modulo 2^64 (checked by a test).
const BASE_INVERSE: u64 = inverse_mod_2_64(BASE);

/// The inverse of an odd `a` modulo 2^64, by Newton's iteration (each step doubles the
/// correct low bits; `a` itself is right to 3 bits since `a * a = 1 mod 8`).
const fn inverse_mod_2_64(a: u64) -> u64 {
    let mut x = a;
    let mut step = 0;
    while step < 5 {
        x = x.wrapping_mul(2u64.wrapping_sub(a.wrapping_mul(x)));
        step += 1;
    }
    x
}

/// A hit spread over 64 bits (SplitMix64's finaliser), so digests of different lists differ.
fn mix(hit: Hit) -> u64 {
    let mut z = ((hit.0 as u64) << 16 | hit.1 as u64).wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// `BASE^n` modulo 2^64.
fn base_power(mut n: u64) -> u64 {
    let (mut result, mut square) = (1u64, BASE);
    while n > 0 {
        if n & 1 == 1 {
            result = result.wrapping_mul(square);
        }
        square = square.wrapping_mul(square);
        n >>= 1;
    }
    result
}

/// The two digests, while they are known.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct HitDigests {
    /// The polynomial digest of the hits in order.
    pub in_order: u64,
    /// The sum of the mixed hits: the same for any order.
    pub as_set: u64,
}

/// The bounding box of a list's hits, inclusive.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct HitBounds {
    pub xmin: u16,
    pub xmax: u16,
    pub ymin: u16,
    pub ymax: u16,
}

impl HitBounds {
    fn of(hit: Hit) -> HitBounds {
        HitBounds {
            xmin: hit.0,
            xmax: hit.0,
            ymin: hit.1,
            ymax: hit.1,
        }
    }

    fn union(self, other: HitBounds) -> HitBounds {
        HitBounds {
            xmin: self.xmin.min(other.xmin),
            xmax: self.xmax.max(other.xmax),
            ymin: self.ymin.min(other.ymin),
            ymax: self.ymax.max(other.ymax),
        }
    }
}

/// A buffer's hits: their count, digests, box and last hit exactly, the first ones listed.
///
/// Nearly every list is empty (every brief tile holds one), so an empty list is a null
/// pointer: a tile's result stays 56 bytes, where the parts held inline made it 120 and
/// storing a trace's results had cost the lazy-grid walk's analytic replay 3-4%.
#[derive(Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(from = "Hits", into = "Hits")]
pub struct HitList {
    /// `None` exactly when the buffer holds no hit.
    held: Option<Box<Hits>>,
}

/// The parts of a list that holds hits (and, serialized, of any list).
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
struct Hits {
    /// Hits the buffer holds.
    #[serde(rename = "count")]
    len: u64,
    /// The first hits, in order (all of them when `listed.len() == len`).
    listed: Vec<Hit>,
    /// `None` once a merge cut the list short before its end.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    digests: Option<HitDigests>,
    /// The box of every hit held (after a cut, of every hit the list ever held: still inside
    /// the tile, since every hit is a passing fragment inside it). `None` when empty.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    bounds: Option<HitBounds>,
    /// The last hit, while it is known (the -1 terminator may overwrite it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    last: Option<Hit>,
}

impl From<Hits> for HitList {
    fn from(hits: Hits) -> HitList {
        HitList {
            held: (hits.len > 0).then(|| Box::new(hits)),
        }
    }
}

impl From<HitList> for Hits {
    fn from(list: HitList) -> Hits {
        list.held.map_or_else(Hits::default, |hits| *hits)
    }
}

impl std::fmt::Debug for HitList {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let empty = Hits::default();
        let hits = self.held.as_deref().unwrap_or(&empty);
        f.debug_struct("HitList")
            .field("len", &hits.len)
            .field("listed", &hits.listed)
            .field("digests", &hits.digests)
            .field("bounds", &hits.bounds)
            .field("last", &hits.last)
            .finish()
    }
}

impl HitList {
    /// A list of `hits`, listing at most `list_cap` of them.
    pub fn from_hits(hits: impl IntoIterator<Item = Hit>, list_cap: usize) -> HitList {
        let mut list = HitList::default();
        hits.into_iter().for_each(|hit| list.push(hit, list_cap));
        list
    }

    /// A list as a trace stores it: its parts, checked against each other.
    pub fn from_parts(
        len: u64,
        listed: Vec<Hit>,
        digests: Option<HitDigests>,
        bounds: Option<HitBounds>,
        last: Option<Hit>,
    ) -> Result<HitList, String> {
        if listed.len() as u64 > len {
            return Err(format!("{} hits listed of {len}", listed.len()));
        }
        if (len == 0) != bounds.is_none() || (len == 0 && last.is_some()) {
            return Err(format!(
                "{len} hits with bounds {bounds:?} and last {last:?}"
            ));
        }
        let inside = |hit: &Hit| {
            bounds.is_some_and(|b| {
                (b.xmin..=b.xmax).contains(&hit.0) && (b.ymin..=b.ymax).contains(&hit.1)
            })
        };
        if let Some(hit) = listed.iter().chain(&last).find(|hit| !inside(hit)) {
            return Err(format!("hit {hit:?} outside the hits' bounds {bounds:?}"));
        }
        if len == 0 && digests.is_some() {
            return Err(format!("no hits with digests {digests:?}"));
        }
        Ok(HitList::from(Hits {
            len,
            listed,
            digests,
            bounds,
            last,
        }))
    }

    /// Append one hit; list it while fewer than `list_cap` are listed and all are.
    #[inline]
    pub fn push(&mut self, hit: Hit, list_cap: usize) {
        self.held.get_or_insert_default().push(hit, list_cap);
    }

    /// Append `other`'s hits after these (listing as [`HitList::push`] would).
    pub fn append(&mut self, other: &HitList, list_cap: usize) {
        if let Some(theirs) = &other.held {
            self.held.get_or_insert_default().append(theirs, list_cap);
        }
    }

    /// Keep the first `n` hits. Dropping only the last keeps the digests; a longer cut loses
    /// them (see the module docs).
    pub fn truncate(&mut self, n: u64) {
        match &mut self.held {
            Some(hits) if n > 0 => hits.truncate(n),
            _ => self.held = None,
        }
    }

    /// Hits the buffer holds.
    pub fn len(&self) -> u64 {
        self.held.as_ref().map_or(0, |hits| hits.len)
    }

    pub fn is_empty(&self) -> bool {
        self.held.is_none()
    }

    /// The first hits, in order.
    pub fn listed(&self) -> &[Hit] {
        self.held.as_ref().map_or(&[], |hits| &hits.listed)
    }

    /// Every hit held is listed.
    pub fn is_fully_listed(&self) -> bool {
        self.held.as_ref().is_none_or(|hits| hits.is_fully_listed())
    }

    /// The digests, unless a merge cut the list short (`None` for an empty list too).
    pub fn digests(&self) -> Option<HitDigests> {
        self.held.as_ref().and_then(|hits| hits.digests)
    }

    /// The box of the hits held (`None` when empty).
    pub fn bounds(&self) -> Option<HitBounds> {
        self.held.as_ref().and_then(|hits| hits.bounds)
    }

    /// The last hit, while known.
    pub fn last(&self) -> Option<Hit> {
        self.held.as_ref().and_then(|hits| hits.last)
    }
}

impl Hits {
    #[inline]
    fn push(&mut self, hit: Hit, list_cap: usize) {
        if self.listed.len() < list_cap && self.is_fully_listed() {
            self.listed.push(hit);
        }
        self.len += 1;
        if let Some(d) = &mut self.digests {
            d.in_order = d.in_order.wrapping_mul(BASE).wrapping_add(mix(hit));
            d.as_set = d.as_set.wrapping_add(mix(hit));
        } else if self.len == 1 {
            self.digests = Some(HitDigests {
                in_order: mix(hit),
                as_set: mix(hit),
            });
        }
        let b = HitBounds::of(hit);
        self.bounds = Some(self.bounds.map_or(b, |old| old.union(b)));
        self.last = Some(hit);
    }

    /// `other` (holding hits) after these.
    fn append(&mut self, other: &Hits, list_cap: usize) {
        if self.is_fully_listed() {
            let room = list_cap.saturating_sub(self.listed.len());
            self.listed.extend(other.listed.iter().take(room).copied());
        }
        self.digests = match (self.len, self.digests, other.digests) {
            (0, _, theirs) => theirs,
            (_, Some(ours), Some(theirs)) => Some(HitDigests {
                in_order: ours
                    .in_order
                    .wrapping_mul(base_power(other.len))
                    .wrapping_add(theirs.in_order),
                as_set: ours.as_set.wrapping_add(theirs.as_set),
            }),
            _ => None,
        };
        self.len += other.len;
        self.bounds = match (self.bounds, other.bounds) {
            (Some(a), Some(b)) => Some(a.union(b)),
            (a, b) => a.or(b),
        };
        self.last = other.last;
    }

    /// The first `n` (at least one) hits.
    fn truncate(&mut self, n: u64) {
        if n >= self.len {
            return;
        }
        match (n + 1 == self.len, self.digests, self.last) {
            (true, Some(d), Some(last)) => {
                let m = mix(last);
                self.digests = Some(HitDigests {
                    in_order: d.in_order.wrapping_sub(m).wrapping_mul(BASE_INVERSE),
                    as_set: d.as_set.wrapping_sub(m),
                });
            }
            _ => self.digests = None,
        }
        self.last = self.listed.get(n as usize - 1).copied();
        self.listed.truncate(n as usize);
        self.len = n;
    }

    fn is_fully_listed(&self) -> bool {
        self.listed.len() as u64 == self.len
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const HITS: [Hit; 5] = [(3, 4), (0, 0), (65535, 7), (3, 4), (9, 65535)];

    #[test]
    fn the_base_inverse_is_an_inverse() {
        assert_eq!(BASE.wrapping_mul(BASE_INVERSE), 1);
    }

    #[test]
    fn the_in_order_digest_is_the_polynomial_of_its_definition() {
        // D(a, b) = mix(a) * B + mix(b), written out for two hits.
        let list = HitList::from_hits([(1, 2), (3, 4)], 0);
        let expected = mix((1, 2)).wrapping_mul(BASE).wrapping_add(mix((3, 4)));
        assert_eq!(list.digests().unwrap().in_order, expected);
        assert_eq!(
            list.digests().unwrap().as_set,
            mix((1, 2)).wrapping_add(mix((3, 4)))
        );
    }

    #[test]
    fn appending_equals_pushing_one_by_one() {
        for split in 0..=HITS.len() {
            let mut joined = HitList::from_hits(HITS[..split].iter().copied(), 3);
            joined.append(&HitList::from_hits(HITS[split..].iter().copied(), 3), 3);
            assert_eq!(joined, HitList::from_hits(HITS, 3), "split at {split}");
        }
    }

    #[test]
    fn order_changes_the_in_order_digest_only() {
        let forward = HitList::from_hits([(1, 2), (3, 4)], 0).digests().unwrap();
        let backward = HitList::from_hits([(3, 4), (1, 2)], 0).digests().unwrap();
        assert_ne!(forward.in_order, backward.in_order);
        assert_eq!(forward.as_set, backward.as_set);
    }

    #[test]
    fn a_list_cut_to_nothing_is_the_empty_list_and_lists_serialize_as_their_parts() {
        let mut cut = HitList::from_hits(HITS, 3);
        cut.truncate(0);
        assert_eq!(cut, HitList::default());
        assert!(cut.is_empty() && cut.is_fully_listed() && cut.listed().is_empty());
        // The JSON a report holds: the parts, an empty list's count and listed hits alone.
        assert_eq!(
            serde_json::to_string(&cut).unwrap(),
            r#"{"count":0,"listed":[]}"#
        );
        let two = HitList::from_hits([(1, 2), (3, 4)], 1);
        let json = serde_json::to_string(&two).unwrap();
        assert!(
            json.starts_with(r#"{"count":2,"listed":[[1,2]],"digests":"#),
            "{json}"
        );
        assert!(json.ends_with(r#""bounds":{"xmin":1,"xmax":3,"ymin":2,"ymax":4},"last":[3,4]}"#));
        assert_eq!(serde_json::from_str::<HitList>(&json).unwrap(), two);
    }

    #[test]
    fn dropping_the_last_hit_gives_the_shorter_list_exactly() {
        for cap in [0, 2, 10] {
            let mut list = HitList::from_hits(HITS, cap);
            list.truncate(4);
            assert_eq!(
                list.digests(),
                HitList::from_hits(HITS[..4].iter().copied(), cap).digests()
            );
            assert_eq!(list.len(), 4);
            assert_eq!(list.listed(), &HITS[..cap.min(4)]);
        }
        let mut single = HitList::from_hits([(1, 1)], 5);
        single.truncate(0);
        assert_eq!(single, HitList::default());
    }

    #[test]
    fn a_longer_cut_loses_the_digests_but_keeps_count_box_and_listed_prefix() {
        let mut list = HitList::from_hits(HITS, 10);
        list.truncate(2);
        assert_eq!((list.len(), list.digests()), (2, None));
        assert_eq!(list.listed(), &HITS[..2]);
        assert_eq!(list.last(), Some(HITS[1]));
        // The box stays that of all five (a superset's, as documented).
        assert_eq!(list.bounds().unwrap().xmax, 65535);
    }

    #[test]
    fn listing_stops_at_the_cap_and_at_the_first_gap() {
        let list = HitList::from_hits(HITS, 2);
        assert_eq!(list.listed(), &HITS[..2]);
        assert!(!list.is_fully_listed());
        // Appended after an incompletely listed list: nothing more is listed.
        let mut joined = HitList::from_hits(HITS, 2);
        joined.append(&HitList::from_hits([(1, 1)], 10), 10);
        assert_eq!(joined.listed(), &HITS[..2]);
    }

    #[test]
    fn parts_that_contradict_each_other_are_refused() {
        assert!(HitList::from_parts(1, vec![(1, 1), (2, 2)], None, None, None).is_err());
        assert!(HitList::from_parts(0, vec![], None, Some(HitBounds::of((0, 0))), None).is_err());
        let bounds = Some(HitBounds::of((5, 5)));
        assert!(HitList::from_parts(1, vec![(6, 5)], None, bounds, Some((6, 5))).is_err());
        let list = HitList::from_hits([(5, 5)], 1);
        let back = HitList::from_parts(1, vec![(5, 5)], list.digests(), bounds, Some((5, 5)));
        assert_eq!(back.unwrap(), list);
    }
}
