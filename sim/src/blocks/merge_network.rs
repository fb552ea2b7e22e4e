//! A merge stage of the two-stage synchronisation: it combines partial query reports (one per
//! Image Engine of a board in stage one, one per board in stage two) into one, and says when
//! the combined report is ready.
//!
//! Function: per tile, counters add (saturating at the counter width), boxes unite, z ranges
//! combine, hit lists concatenate in input order and keep at most the buffer's hit room (a
//! longer list marks the buffer overflowed). Truncating at every node keeps a prefix of the
//! whole concatenation, so the merged report does not depend on the network's shape.
//!
//! Traffic: a report is `W = 8 T + H` 32-bit words (`T` tiles, a brief record of 8 words
//! each, every Image Engine sending every tile; `H` the verbose hits it holds, per tile at most
//! the buffer's hit room). It crosses a link of `w` bits a cycle in `x(W) = ceil(32 W / w)`
//! cycles (`x = 0` for an unlimited link, `w = 0`). A merged report holds, per tile, the sum
//! of its inputs' hits up to the room.
//!
//! Timing, inputs ready in `r_0 .. r_{n-1}` with `W_0 .. W_{n-1}` words (hop latency `h`,
//! read latency `L`, host read cycles per word `c`):
//! - tree: inputs pair up level by level, `(0, 1), (2, 3), ...`; a pair's merged report is
//!   ready in `max(left + x(W_left), right + x(W_right)) + h` (each child's report crosses its
//!   own link); an unpaired last input moves up unchanged; the root's time is the stage's
//!   output (one input: no hop);
//! - chain: `c_0 = r_0`, `c_i = max(r_i, c_{i-1} + x(W of c_{i-1}) + h)`: the carried report
//!   crosses one link to the next input; the output is `c_{n-1}`;
//! - software: the host reads the inputs one at a time in order, word by word:
//!   `host = max(host, r_i) + L + c W_i`; the output is the host's time after the last read.
//!   The host is one reader for both stages and all queries, so its reads never overlap.
//!
//! After a hardware global merge the final report goes to host memory by DMA, `x(W)` cycles
//! at the DMA's width ([`MergeState::deliver`]); a software merge has it in the host already. With
//! unlimited links (`x = 0`), the rules are those of a merge that moves no words.
//!
//! Links carry one report at a time, in order: a report ready in `r` crosses its link from
//! `max(r, f)`, `f` the cycle the link's report before it (an earlier query's) has crossed,
//! and the DMA likewise ([`MergeState`], which the machine carries from query to query).
//! (Without it, back-to-back queries of 256 tiles on ir4 crossed the same links at full
//! rate at once, each answered some 21,000 cycles after its end whether the one before had
//! been or not.)

use crate::arch::{MergeKind, MergeNetwork, OCCU_WORD_BITS};
use occsim_traces::hit_list::listed_hits_per_tile;
use occsim_traces::query::BRIEF_RECORD_ENTRIES;
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

/// A partial report on its way through a merge: the cycle it is ready and the hits it holds
/// per tile (empty without verbose hits; one bucket for a whole-report count).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Partial {
    pub ready: u64,
    pub hits: Vec<u64>,
}

impl Partial {
    /// A report without hits (a brief, samples or any query's).
    pub fn brief(ready: u64) -> Partial {
        Partial {
            ready,
            hits: Vec::new(),
        }
    }

    /// Its 32-bit words: a brief record for each of `tiles` tiles and the hits.
    pub fn words(&self, tiles: u64) -> u64 {
        tiles * BRIEF_RECORD_ENTRIES as u64 + self.hits.iter().sum::<u64>()
    }

    /// Merge `other`'s hits into these: per tile the sum, kept within `room`, a tile only
    /// one of them holds as it is. In place: a verbose query's merges on ir4 had allocated
    /// a list for every one of their 319 merges.
    fn merge_hits(&mut self, other: &Partial, room: u64) {
        let shared = self.hits.len().min(other.hits.len());
        for (h, s) in self.hits.iter_mut().zip(&other.hits) {
            *h = (*h + s).min(room);
        }
        self.hits.extend_from_slice(&other.hits[shared..]);
    }
}

/// The shape of the reports a stage merges: tiles and the verbose buffers' hit room.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ReportShape {
    pub tiles: u64,
    /// Hits a tile's merged report keeps (`u64::MAX`: no limit).
    pub room: u64,
}

/// Cycles `words` 32-bit words take over a link of `bits_per_cycle` (0: unlimited).
pub fn transfer_cycles(words: u64, bits_per_cycle: u64) -> u64 {
    if bits_per_cycle == 0 {
        0
    } else {
        (words * OCCU_WORD_BITS as u64).div_ceil(bits_per_cycle)
    }
}

/// When each link of a merge stage is free: the cycle the last report over it has crossed
/// (numbered as the stage's rules meet them: a tree's level by level, each input's link to
/// its pair, a chain's the carried report's link into input `i`).
#[derive(Clone, Debug, Default)]
pub struct MergeLinks {
    free: Vec<u64>,
}

impl MergeLinks {
    /// A report ready in `ready` crosses link `link` in `cycles`, after the link's report
    /// before it: the cycle it has crossed.
    fn cross(&mut self, link: usize, ready: u64, cycles: u64) -> u64 {
        if link >= self.free.len() {
            self.free.resize(link + 1, 0);
        }
        let crossed = ready.max(self.free[link]) + cycles;
        self.free[link] = crossed;
        crossed
    }
}

/// What the two merge stages carry from query to query: the host's first free cycle
/// (software merges advance it), each board's stage-one links, stage two's, and when the
/// DMA to host memory is free.
#[derive(Clone, Debug, Default)]
pub struct MergeState {
    pub host: u64,
    local: Vec<MergeLinks>,
    global: MergeLinks,
    dma: u64,
}

impl MergeState {
    /// Board `board`'s stage one over its Image Engines' reports (in order).
    pub fn local(
        &mut self,
        network: &MergeNetwork,
        board: usize,
        inputs: &[Partial],
        shape: ReportShape,
    ) -> Partial {
        self.grow_to(board);
        merged_ready(
            network,
            inputs,
            shape,
            &mut self.host,
            &mut self.local[board],
        )
    }

    /// [`Self::local`] of reports without hits, given their ready cycles (overwritten).
    pub fn local_brief(
        &mut self,
        network: &MergeNetwork,
        board: usize,
        ready: &mut [u64],
        tiles: u64,
    ) -> u64 {
        self.grow_to(board);
        merged_ready_brief(
            network,
            ready,
            tiles,
            &mut self.host,
            &mut self.local[board],
        )
    }

    /// Stage two over the boards' merged reports (in board order).
    pub fn global(
        &mut self,
        network: &MergeNetwork,
        inputs: &[Partial],
        shape: ReportShape,
    ) -> Partial {
        merged_ready(network, inputs, shape, &mut self.host, &mut self.global)
    }

    /// [`Self::global`] of reports without hits, given their ready cycles (overwritten).
    pub fn global_brief(&mut self, network: &MergeNetwork, ready: &mut [u64], tiles: u64) -> u64 {
        merged_ready_brief(network, ready, tiles, &mut self.host, &mut self.global)
    }

    /// The cycle the final report is in host memory: after a hardware stage two, its output
    /// written by DMA in `x(W)` cycles at `dma_bits_per_cycle`, once the DMA is through the
    /// report before it; a software merge's is the host's already.
    pub fn deliver(
        &mut self,
        global: &MergeNetwork,
        merged: &Partial,
        shape: ReportShape,
        dma_bits_per_cycle: u64,
    ) -> u64 {
        match global.kind {
            MergeKind::Software => merged.ready,
            MergeKind::Tree | MergeKind::Chain => {
                let writing = transfer_cycles(merged.words(shape.tiles), dma_bits_per_cycle);
                self.dma = merged.ready.max(self.dma) + writing;
                self.dma
            }
        }
    }

    /// The same state on a clock `base` cycles later (a machine started mid-trace counts
    /// from there): every cycle `base` sooner, none before 0.
    pub fn moved_back(&self, base: u64) -> MergeState {
        let back = |cycle: &u64| cycle.saturating_sub(base);
        let links = |links: &MergeLinks| MergeLinks {
            free: links.free.iter().map(back).collect(),
        };
        MergeState {
            host: back(&self.host),
            local: self.local.iter().map(links).collect(),
            global: links(&self.global),
            dma: back(&self.dma),
        }
    }

    /// Room for board `board`'s stage-one links.
    fn grow_to(&mut self, board: usize) {
        if board >= self.local.len() {
            self.local.resize_with(board + 1, MergeLinks::default);
        }
    }
}

/// A stage's merged report (ready cycle and hits), given its inputs in order, over `links`
/// (each report after the one before it on its link). `host` is the host's first free
/// cycle (software merges advance it).
pub fn merged_ready(
    network: &MergeNetwork,
    inputs: &[Partial],
    shape: ReportShape,
    host: &mut u64,
    links: &mut MergeLinks,
) -> Partial {
    let crossing = |p: &Partial| transfer_cycles(p.words(shape.tiles), network.link_bits_per_cycle);
    if inputs.iter().all(|p| p.hits.is_empty()) {
        let mut ready: Vec<u64> = inputs.iter().map(|p| p.ready).collect();
        let ready = merged_ready_brief(network, &mut ready, shape.tiles, host, links);
        return Partial::brief(ready);
    }
    match network.kind {
        MergeKind::Tree => {
            // Each level merged in place: pair `i` into slot `i` (slots before `2 i` are
            // read already).
            let mut level = inputs.to_vec();
            let mut first_link = 0;
            while level.len() > 1 {
                let merged = level.len().div_ceil(2);
                for i in 0..merged {
                    let mut left = std::mem::take(&mut level[2 * i]);
                    if let Some(right) = level.get(2 * i + 1) {
                        let link = first_link + 2 * i;
                        let left_in = links.cross(link, left.ready, crossing(&left));
                        let right_in = links.cross(link + 1, right.ready, crossing(right));
                        left.ready = left_in.max(right_in) + network.hop_latency_cycles;
                        left.merge_hits(right, shape.room);
                    }
                    level[i] = left;
                }
                first_link += level.len();
                level.truncate(merged);
            }
            level.pop().unwrap_or(Partial::brief(0))
        }
        MergeKind::Chain => {
            let mut inputs = inputs.iter().cloned().enumerate();
            let Some((_, mut carried)) = inputs.next() else {
                return Partial::brief(0);
            };
            for (link, input) in inputs {
                let arrived = links.cross(link, carried.ready, crossing(&carried));
                carried.ready = input.ready.max(arrived + network.hop_latency_cycles);
                carried.merge_hits(&input, shape.room);
            }
            carried
        }
        MergeKind::Software => {
            let mut merged = Partial::brief(0);
            for input in inputs {
                *host = (*host).max(input.ready)
                    + network.read_latency_cycles
                    + network.read_cycles_per_word * input.words(shape.tiles);
                merged.merge_hits(input, shape.room);
            }
            merged.ready = *host;
            merged
        }
    }
}

/// [`merged_ready`] of reports without hits (a brief, samples or any query's, `tiles`
/// tiles each), given their ready cycles in order, which it overwrites: the same cycle,
/// without a report built for each input (a query's end on ir4 had built 320).
pub fn merged_ready_brief(
    network: &MergeNetwork,
    ready: &mut [u64],
    tiles: u64,
    host: &mut u64,
    links: &mut MergeLinks,
) -> u64 {
    let words = tiles * BRIEF_RECORD_ENTRIES as u64;
    let crossing = transfer_cycles(words, network.link_bits_per_cycle);
    let hop = network.hop_latency_cycles;
    match network.kind {
        MergeKind::Tree => {
            // Every report crosses a link in the same cycles: the tree's levels as ready
            // cycles alone, each merged in place.
            let (mut len, mut first_link) = (ready.len(), 0);
            while len > 1 {
                let merged = len.div_ceil(2);
                for i in 0..merged {
                    ready[i] = match (2 * i + 1 < len).then(|| ready[2 * i + 1]) {
                        Some(right) => {
                            let link = first_link + 2 * i;
                            let left_in = links.cross(link, ready[2 * i], crossing);
                            let right_in = links.cross(link + 1, right, crossing);
                            left_in.max(right_in) + hop
                        }
                        None => ready[2 * i],
                    };
                }
                first_link += len;
                len = merged;
            }
            ready.first().copied().unwrap_or(0)
        }
        MergeKind::Chain => {
            let Some((&first, rest)) = ready.split_first() else {
                return 0;
            };
            let mut carried = first;
            for (index, &input) in rest.iter().enumerate() {
                let arrived = links.cross(index + 1, carried, crossing);
                carried = input.max(arrived + hop);
            }
            carried
        }
        MergeKind::Software => {
            for &input in ready.iter() {
                *host = (*host).max(input)
                    + network.read_latency_cycles
                    + network.read_cycles_per_word * words;
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
            link_bits_per_cycle: 0,
            read_cycles_per_word: 0,
        }
    }

    /// [`merged_ready`] on links that carry no other report (the query merged alone).
    fn merged_alone(
        network: &MergeNetwork,
        inputs: &[Partial],
        shape: ReportShape,
        host: &mut u64,
    ) -> Partial {
        merged_ready(network, inputs, shape, host, &mut MergeLinks::default())
    }

    fn ready(cycles: &[u64]) -> Vec<Partial> {
        cycles.iter().map(|&r| Partial::brief(r)).collect()
    }

    const ONE_TILE: ReportShape = ReportShape {
        tiles: 1,
        room: u64::MAX,
    };

    #[test]
    fn hand_worked_merge_times() {
        let inputs = ready(&[5, 30, 7, 8, 9]);
        let mut host = 0;
        let at = |kind, host: &mut u64| merged_alone(&network(kind), &inputs, ONE_TILE, host).ready;
        // Tree: (5,30)->40, (7,8)->18, 9 -> [40, 18, 9] -> (40,18)->50, 9 -> 60.
        assert_eq!(at(MergeKind::Tree, &mut host), 60);
        // Chain: 5, max(30, 15)=30, max(7, 40)=40, 50, 60.
        assert_eq!(at(MergeKind::Chain, &mut host), 60);
        assert_eq!(host, 0, "hardware merges leave the host alone");
        // Software: 105, 205, 305, 405, 505.
        assert_eq!(at(MergeKind::Software, &mut host), 505);
        assert_eq!(host, 505);
        let single = merged_alone(
            &network(MergeKind::Tree),
            &ready(&[17]),
            ONE_TILE,
            &mut host,
        );
        assert_eq!(single.ready, 17);
    }

    #[test]
    fn merge_latency_grows_with_the_words_moved() {
        // Four inputs ready in 0, 2 tiles (16 words each), 64-bit links, hop 10:
        // every link crossing takes ceil(16 * 32 / 64) = 8 cycles.
        let links = |kind| MergeNetwork {
            link_bits_per_cycle: 64,
            read_cycles_per_word: 3,
            ..network(kind)
        };
        let two_tiles = ReportShape {
            tiles: 2,
            room: u64::MAX,
        };
        let inputs = ready(&[0, 0, 0, 0]);
        let mut host = 0;
        // Tree: two levels of (8 + 10): 18, then 36.
        let tree = merged_alone(&links(MergeKind::Tree), &inputs, two_tiles, &mut host);
        assert_eq!(tree.ready, 36);
        // Chain: 0, 0+8+10=18, 36, 54.
        let chain = merged_alone(&links(MergeKind::Chain), &inputs, two_tiles, &mut host);
        assert_eq!(chain.ready, 54);
        // Software: each read 100 + 3 * 16 = 148: 148, 296, 444, 592.
        let software = merged_alone(&links(MergeKind::Software), &inputs, two_tiles, &mut host);
        assert_eq!(software.ready, 592);
        // Twice the tiles, twice the words: 16 cycles a crossing, the tree 2 * (16 + 10) = 52.
        let four_tiles = ReportShape {
            tiles: 4,
            ..two_tiles
        };
        let mut host = 0;
        let tree = merged_alone(&links(MergeKind::Tree), &inputs, four_tiles, &mut host);
        assert_eq!(tree.ready, 52);
        // Verbose hits add words: one tile with 24 hits in each of two inputs, room 40:
        // each input 8 + 24 = 32 words (16 cycles on 64 bits); the merged holds min(48, 40).
        let verbose: Vec<Partial> = (0..2)
            .map(|_| Partial {
                ready: 0,
                hits: vec![24],
            })
            .collect();
        let shape = ReportShape { tiles: 1, room: 40 };
        let merged = merged_alone(&links(MergeKind::Tree), &verbose, shape, &mut host);
        assert_eq!((merged.ready, merged.hits.clone()), (16 + 10, vec![40]));
        assert_eq!(merged.words(1), 48);
        // On a 32-bit link a word a cycle: 32 + 10.
        let narrow = MergeNetwork {
            link_bits_per_cycle: 32,
            ..links(MergeKind::Tree)
        };
        assert_eq!(merged_alone(&narrow, &verbose, shape, &mut host).ready, 42);
    }

    #[test]
    fn a_tree_of_reports_without_hits_merges_as_one_with_empty_hit_counts() {
        // Reports without hits take the tree's shortcut (ready cycles alone); the same
        // reports each with a tile's count of 0 hits move the same words the long way.
        let links = MergeNetwork {
            link_bits_per_cycle: 64,
            ..network(MergeKind::Tree)
        };
        let shape = ReportShape { tiles: 3, room: 40 };
        let mut rng = occsim_traces::rng::SplitMix64(15);
        for count in 1..=21 {
            let brief: Vec<Partial> = (0..count)
                .map(|_| Partial::brief(rng.below(1000)))
                .collect();
            let counted: Vec<Partial> = brief
                .iter()
                .map(|p| Partial {
                    ready: p.ready,
                    hits: vec![0; 3],
                })
                .collect();
            let mut host = 0;
            let short = merged_alone(&links, &brief, shape, &mut host).ready;
            let long = merged_alone(&links, &counted, shape, &mut host).ready;
            assert_eq!(short, long, "{count} reports");
        }
    }

    #[test]
    fn a_report_crosses_its_link_after_the_one_before_it() {
        // Two inputs, one tile (8 words) each, 32-bit links (8 cycles a crossing), hop 10.
        // Query 1's reports are ready in 0 and 0: both links busy 0-8, merged in 18. Query
        // 2's are ready in 4 and 20: the first waits for its link until 8 (in 16), the
        // second crosses 20-28; merged in 38. On fresh links the first would have been in
        // by 12 and the merge the same, 38; ready in 4 and 5, it is 16 + 10 = 26 against
        // fresh links' 13 + 10 = 23.
        let tree = MergeNetwork {
            link_bits_per_cycle: 32,
            ..network(MergeKind::Tree)
        };
        let (mut host, mut links) = (0, MergeLinks::default());
        let mut merge = |ready: &[u64], links: &mut MergeLinks| {
            merged_ready(
                &tree,
                &super::tests::ready(ready),
                ONE_TILE,
                &mut host,
                links,
            )
            .ready
        };
        assert_eq!(merge(&[0, 0], &mut links), 18);
        let mut after = links.clone();
        assert_eq!(merge(&[4, 20], &mut links), 38);
        assert_eq!(merge(&[4, 5], &mut after), 26);
        assert_eq!(merge(&[4, 5], &mut MergeLinks::default()), 23);
        // The brief path keeps the same links: the same cycles.
        let mut brief_links = MergeLinks::default();
        let brief = |ready: &[u64], links: &mut MergeLinks| {
            merged_ready_brief(&tree, &mut ready.to_vec(), 1, &mut 0, links)
        };
        assert_eq!(brief(&[0, 0], &mut brief_links), 18);
        assert_eq!(brief(&[4, 5], &mut brief_links), 26);
        // A chain's carried report crosses into input 1, then 2: 8 + 10 each. Query 1 from
        // 0, 0, 0: in by 8, merged 18; in by 26, merged 36. Query 2 ready in 1, 1, 1: its
        // first crossing waits for 8 (in 16, merged 26), its second for 26 (in 34, 44).
        let chain = MergeNetwork {
            link_bits_per_cycle: 32,
            ..network(MergeKind::Chain)
        };
        let mut chain_links = MergeLinks::default();
        for (ready, merged) in [([0, 0, 0], 36), ([1, 1, 1], 44)] {
            let reports = super::tests::ready(&ready);
            let long = merged_ready(&chain, &reports, ONE_TILE, &mut 0, &mut chain_links.clone());
            let short =
                merged_ready_brief(&chain, &mut ready.to_vec(), 1, &mut 0, &mut chain_links);
            assert_eq!((long.ready, short), (merged, merged));
        }
    }

    #[test]
    fn the_dma_takes_one_report_at_a_time() {
        // 8 words at 16 bits a cycle: 16 cycles each. Two reports merged by 10 and 12:
        // in host memory by 26, then 42.
        let global = MergeNetwork {
            link_bits_per_cycle: 32,
            ..network(MergeKind::Tree)
        };
        let mut state = MergeState::default();
        let first = state.deliver(&global, &Partial::brief(10), ONE_TILE, 16);
        let second = state.deliver(&global, &Partial::brief(12), ONE_TILE, 16);
        assert_eq!((first, second), (26, 42));
    }

    #[test]
    fn unlimited_links_and_no_latency_merge_in_no_time() {
        let free = |kind| MergeNetwork {
            kind,
            hop_latency_cycles: 0,
            read_latency_cycles: 0,
            link_bits_per_cycle: 0,
            read_cycles_per_word: 0,
        };
        let shape = ReportShape {
            tiles: 1024,
            room: u64::MAX,
        };
        let inputs = ready(&[5, 30, 7, 8, 9]);
        for kind in [MergeKind::Tree, MergeKind::Chain, MergeKind::Software] {
            let mut host = 0;
            assert_eq!(
                merged_alone(&free(kind), &inputs, shape, &mut host).ready,
                30
            );
        }
        assert_eq!(transfer_cycles(1 << 20, 0), 0);
        assert_eq!(
            transfer_cycles(3, 64),
            2,
            "96 bits on a 64-bit link: two cycles"
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
