//! A merge stage of the two-stage synchronisation: it combines partial query reports (one per
//! Image Engine of a board in stage one, one per board in stage two) into one, and says when
//! the combined report is ready.
//!
//! Function: per tile, counters add (saturating at the counter width), boxes unite, z ranges
//! combine, hit lists concatenate in input order and keep at most the buffer's hit room (a
//! longer list marks the buffer overflowed). Truncating at every node keeps a prefix of the
//! whole concatenation, so the merged report does not depend on the network's shape.
//!
//! Timing, inputs ready in `r_0 .. r_{n-1}` (hop latency `h`, read latency `L`):
//! - tree: inputs pair up level by level, `(0, 1), (2, 3), ...`; a pair's merged report is
//!   ready in `max(left, right) + h`; an unpaired last input moves up unchanged; the root's
//!   time is the stage's output (one input: no hop);
//! - chain: `c_0 = r_0`, `c_i = max(r_i, c_{i-1} + h)`; the output is `c_{n-1}`;
//! - software: the host reads the inputs one at a time in order:
//!   `host = max(host, r_i) + L`; the output is the host's time after the last read. The
//!   host is one reader for both stages and all queries, so its reads never overlap.

use crate::arch::{MergeKind, MergeNetwork};
use occsim_traces::hit_list::listed_hits_per_tile;
use occsim_traces::TileResult;

/// Fold `part` into `total`: counters saturate at `counter_max`, hit lists keep `hit_room`.
pub fn merge_partial(
    total: &mut [TileResult],
    part: &[TileResult],
    counter_max: u64,
    hit_room: usize,
) {
    let list_cap = listed_hits_per_tile(total.len());
    for (t, p) in total.iter_mut().zip(part) {
        t.merge(p, list_cap);
        t.nohc = t.nohc.min(counter_max);
        t.phc = t.phc.min(counter_max);
        if t.hits.len() > hit_room as u64 {
            t.hits.truncate(hit_room as u64);
            t.overflowed = true;
        }
    }
}

/// The cycle a stage's merged report is ready, given its inputs' ready cycles in order.
/// `host` is the host's first free cycle (software merges advance it).
pub fn merged_ready(network: &MergeNetwork, inputs: &[u64], host: &mut u64) -> u64 {
    match network.kind {
        MergeKind::Tree => {
            let mut level = inputs.to_vec();
            while level.len() > 1 {
                level = level
                    .chunks(2)
                    .map(|pair| match pair {
                        [left, right] => (*left).max(*right) + network.hop_latency_cycles,
                        [single] => *single,
                        _ => unreachable!("chunks of two"),
                    })
                    .collect();
            }
            level.first().copied().unwrap_or(0)
        }
        MergeKind::Chain => inputs
            .iter()
            .copied()
            .reduce(|carried, ready| ready.max(carried + network.hop_latency_cycles))
            .unwrap_or(0),
        MergeKind::Software => {
            for &ready in inputs {
                *host = (*host).max(ready) + network.read_latency_cycles;
            }
            *host
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use occsim_traces::HitList;

    fn network(kind: MergeKind) -> MergeNetwork {
        MergeNetwork {
            kind,
            hop_latency_cycles: 10,
            read_latency_cycles: 100,
        }
    }

    #[test]
    fn hand_worked_merge_times() {
        let inputs = [5, 30, 7, 8, 9];
        let mut host = 0;
        // Tree: (5,30)->40, (7,8)->18, 9 -> [40, 18, 9] -> (40,18)->50, 9 -> 60.
        assert_eq!(
            merged_ready(&network(MergeKind::Tree), &inputs, &mut host),
            60
        );
        // Chain: 5, max(30, 15)=30, max(7, 40)=40, 50, 60.
        assert_eq!(
            merged_ready(&network(MergeKind::Chain), &inputs, &mut host),
            60
        );
        assert_eq!(host, 0, "hardware merges leave the host alone");
        // Software: 105, 205, 305, 405, 505.
        assert_eq!(
            merged_ready(&network(MergeKind::Software), &inputs, &mut host),
            505
        );
        assert_eq!(host, 505);
        assert_eq!(
            merged_ready(&network(MergeKind::Tree), &[17], &mut host),
            17
        );
    }

    #[test]
    fn hit_lists_concatenate_within_the_room() {
        let part = |hits: Vec<(u16, u16)>| TileResult {
            nohc: hits.len() as u64,
            hits: HitList::from_hits(hits, 10),
            phc: 9,
            xmin: 1,
            xmax: 1,
            ..TileResult::default()
        };
        let mut total = vec![TileResult::default()];
        merge_partial(&mut total, &[part(vec![(1, 0), (1, 1)])], 10, 3);
        merge_partial(&mut total, &[part(vec![(1, 2), (1, 3)])], 10, 3);
        assert_eq!(total[0].hits.listed(), [(1, 0), (1, 1), (1, 2)]);
        assert_eq!(total[0].hits.len(), 3);
        assert!(total[0].overflowed);
        assert_eq!(
            (total[0].nohc, total[0].phc),
            (4, 10),
            "phc saturates at 10"
        );
    }
}
