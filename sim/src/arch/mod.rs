//! Architecture files: every timing parameter of a machine, with its unit and meaning.
//!
//! Each parameter is declared once (`declare.rs`'s `parameters!`): its field in the typed
//! struct the models read ([`O2Arch`], [`IrArch`], and [`OccuArch`], the Occlusion Unit's
//! group composed into both), and from the same line its entry in the machine's documented
//! table ([`O2_PARAMS`], [`IR_PARAMS`]), from which the built-in defaults are built, `arch
//! show` prints, and TOML files and `--set key=value` are validated. A file names its machine
//! and holds one section per machine:
//!
//! ```toml
//! machine = "o2"
//!
//! [o2]
//! clock_mhz = 66.67
//! engines = 4
//! ```
//!
//! Keys carry their unit (`_mhz`, `_cycles`, `_entries`, `_bits`, ...). The
//! InfiniteReality-like machine has its own table and `[ir]` section (`machine = "ir"`); the
//! built-ins `ir1`, `ir2`, `ir4` are its defaults with 1, 2 or 4 boards. Named choices
//! (`interleave = "morton"`) are TOML strings, and bare names with `--set`.

use occsim_traces::depth_layout::DepthLayout;
use std::fmt::Write as _;
use thiserror::Error;

/// The type and legal range of one parameter.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ParamKind {
    /// A real number in `min..=max`.
    Float {
        min: f64,
        max: f64,
    },
    /// An unsigned integer in `min..=max`.
    Int {
        min: u64,
        max: u64,
    },
    Bool,
    /// One of a fixed set of names.
    Choice {
        choices: &'static [&'static str],
    },
}

/// One parameter's value.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Value {
    Float(f64),
    Int(u64),
    Bool(bool),
    /// A name from the parameter's choices.
    Choice(&'static str),
}

/// One resolved parameter, as reports list them; in JSON its value is a number, a boolean
/// or (for a named choice) a string.
#[derive(Clone, Debug, serde::Serialize, PartialEq)]
pub struct ArchEntry {
    pub key: String,
    pub value: Value,
    pub unit: String,
}

/// As JSON: a number, a boolean, or a choice's name as a string.
impl serde::Serialize for Value {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        match *self {
            Value::Float(v) => serializer.serialize_f64(v),
            Value::Int(v) => serializer.serialize_u64(v),
            Value::Bool(v) => serializer.serialize_bool(v),
            Value::Choice(v) => serializer.serialize_str(v),
        }
    }
}

impl std::fmt::Display for Value {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            // `{:?}` keeps a decimal point, so the text reads back as a TOML float.
            Value::Float(v) => write!(f, "{v:?}"),
            Value::Int(v) => write!(f, "{v}"),
            Value::Bool(v) => write!(f, "{v}"),
            // Quoted, so the text reads back as a TOML string.
            Value::Choice(v) => write!(f, "\"{v}\""),
        }
    }
}

/// A parameter's declaration: name (with unit suffix), unit, default, range, meaning and
/// provenance.
#[derive(Clone, Copy, Debug)]
pub struct Param {
    pub key: &'static str,
    pub unit: &'static str,
    pub default: Value,
    pub kind: ParamKind,
    pub meaning: &'static str,
    pub provenance: Provenance,
}

/// Where a parameter's default comes from (see `shared/reference/occlusion-unit.md`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Mark {
    /// Read in a primary source (a datasheet, the paper, the vendor's documents or code).
    V,
    /// Read in a secondary source (a review, a textbook, a summary of the vendor's figures).
    V2,
    /// Our inference: a plausible range and the reason come with it.
    I,
}

impl Mark {
    pub fn name(self) -> &'static str {
        match self {
            Mark::V => "V",
            Mark::V2 => "V2",
            Mark::I => "I",
        }
    }
}

/// A parameter's provenance: its mark, the source (V, V2) or reason (I), and for an inference
/// the plausible range `low..=high` in the parameter's unit (for a named choice, two
/// alternatives), which the sensitivity analysis varies it over.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Provenance {
    pub mark: Mark,
    pub plausible: Option<(Value, Value)>,
    pub source: &'static str,
}

impl std::fmt::Display for Provenance {
    /// `V: source`, `V2: source` or `I 100..1000: reason`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.plausible {
            Some((low, high)) => write!(
                f,
                "{} {}..{}: {}",
                self.mark.name(),
                plain(low),
                plain(high),
                self.source
            ),
            None => write!(f, "{}: {}", self.mark.name(), self.source),
        }
    }
}

/// A value as a reader writes it in prose: choices without quotes.
fn plain(value: Value) -> String {
    match value {
        Value::Choice(name) => name.to_string(),
        other => other.to_string(),
    }
}

impl Param {
    /// The plausible range of an inference (`None` for a sourced value).
    pub fn plausible(&self) -> Option<(Value, Value)> {
        self.provenance.plausible
    }

    /// Whether `value` lies in the plausible range (a sourced value has none: any legal
    /// value is as good as another).
    pub fn is_plausible(&self, value: Value) -> bool {
        match self.provenance.plausible {
            None => true,
            Some((low, high)) => within(value, low, high),
        }
    }

    /// The rules every declaration keeps: an inference has a plausible range and a sourced
    /// value none; the range is ordered, legal, and holds the default.
    pub fn check_provenance(&self) -> Result<(), String> {
        let p = &self.provenance;
        if p.source.is_empty() {
            return Err("no source or reason".to_string());
        }
        match (p.mark, p.plausible) {
            (Mark::I, None) => Err("an inference needs a plausible range".to_string()),
            (Mark::V | Mark::V2, Some(_)) => {
                Err("only an inference has a plausible range".to_string())
            }
            (_, None) => Ok(()),
            (Mark::I, Some((low, high))) => {
                let legal = |v: Value| match self.kind {
                    ParamKind::Float { min, max } => {
                        within(v, Value::Float(min), Value::Float(max))
                    }
                    ParamKind::Int { min, max } => within(v, Value::Int(min), Value::Int(max)),
                    ParamKind::Bool => matches!(v, Value::Bool(_)),
                    ParamKind::Choice { choices } => {
                        matches!(v, Value::Choice(name) if choices.contains(&name))
                    }
                };
                if !legal(low) || !legal(high) {
                    return Err(format!(
                        "plausible range {}..{} outside the legal range",
                        plain(low),
                        plain(high)
                    ));
                }
                if !within(self.default, low, high) {
                    return Err(format!(
                        "plausible range {}..{} does not hold the default {}",
                        plain(low),
                        plain(high),
                        plain(self.default)
                    ));
                }
                Ok(())
            }
        }
    }
}

/// `low <= value <= high` for numbers; for a flag or a choice, `value` is one of the two.
fn within(value: Value, low: Value, high: Value) -> bool {
    match (value, low, high) {
        (Value::Int(v), Value::Int(l), Value::Int(h)) => l <= v && v <= h,
        (Value::Float(v), Value::Float(l), Value::Float(h)) => l <= v && v <= h,
        _ => value == low || value == high,
    }
}

impl ParamKind {
    fn describe(&self) -> String {
        match self {
            ParamKind::Float { min, max } => format!("a number in {min:?}..={max:?}"),
            ParamKind::Int { min, max } => format!("an integer in {min}..={max}"),
            ParamKind::Bool => "true or false".to_string(),
            ParamKind::Choice { choices } => format!("one of {}", choices.join(", ")),
        }
    }
}

mod declare;

use declare::{parameters, Cursor, Named};
use std::sync::LazyLock;

parameters! {
    /// The Occlusion Unit's parameters: the same on both machines, declared once and
    /// composed into each (the O2's one unit, every InfiniteReality Image Engine's own).
    pub struct OccuArch {
        engines: usize = 4, [1, 1024], "engines", "occlusion engines in the Occlusion Unit (at the IR, in every Image Engine's); tiles are dealt to them round-robin",
            I [1, 16] "the paper replicates engines inside one unit without giving a count; 1 is the least, 16 tiles a query the most its examples use";
        counter_bits: u32 = 32, [1, 64], "bits", "width of the NOHC and PHC counters; they saturate at 2^bits - 1",
            V "OpenGL 4.6: SAMPLES_PASSED counters of at least 32 bits";
        all_tiles_one_cycle: bool = false, "bool", "what-if: an engine tests all its tiles in one cycle instead of one tile per cycle",
            V "the paper: an engine that holds k tiles spends k cycles per fragment (false)";
        occu_write_buffer_words: usize = 32, [1, 1 << 20], "words", "OccU Control's write buffer in 32-bit words (O2: records and hits; IR: hit words, drained one a cycle at each Image Engine); full stalls the engines",
            I [8, 128] "not published; a few 256-bit memory words (one is 8 record words), the size of the era's write buffers";
    }
}

parameters! {
    /// The O2-like machine's parameters, typed, each with its provenance (see
    /// `shared/reference/occlusion-unit.md`).
    pub struct O2Arch {
        clock_mhz: f64 = 66.67, [0.001, 100_000.0], "MHz", "rendering engine clock; one pipeline cycle",
            V "Linux crime.h: the CRIME rendering engine at 66.67 MHz";
        primitive_setup_cycles: u64 = 4, [0, 1 << 20], "cycles/primitive", "rasterizer cycles spent setting up each primitive before its first fragment",
            I [2, 16] "not published; edge and depth slopes of one triangle, a few cycles in a fixed-function setup unit";
        fifo_raster_to_depth_entries: usize = 16, [1, 1 << 16], "fragments", "FIFO between rasterizer and depth/stencil pipeline",
            I [4, 64] "not published; enough to cover the page-miss latency at one fragment a cycle, at most what an on-chip FIFO of the era held";
        prefetch_depth_fragments: usize = 16, [1, 1 << 16], "fragments", "how many fragments ahead of the depth test the prefetch buffer may issue depth reads",
            I [4, 64] "the O2 prefetches depth to hide memory latency (V: the paper), how far ahead is not published; at least the miss latency, at most the FIFO ahead of it";
        page_hit_latency_cycles: u64 = 2, [1, 1 << 16], "cycles", "depth read latency, request to data, when the word lies in the same 64 KB tile as the previous read",
            I [2, 6] "CAS 2 (V, SGI O2 documents) is the DRAM's column access alone; the port's request and the data's return add an unpublished 0-4 cycles";
        page_miss_latency_cycles: u64 = 8, [1, 1 << 16], "cycles", "depth read latency when the word lies in another 64 KB tile",
            I [6, 10] "precharge and row activation of SDRAM of the era (2-3 cycles each) on top of the page hit";
        framebuffer_tile_width_pixels: u32 = 128, [1, 1 << 14], "pixels", "width of one depth buffer tile (one memory page)",
            V "Linux gbefb.c: 64 KB tiles, 128x128 pixels at 32 bpp";
        framebuffer_tile_height_pixels: u32 = 128, [1, 1 << 14], "pixels", "height of one depth buffer tile (one memory page)",
            V "Linux gbefb.c: 64 KB tiles, 128x128 pixels at 32 bpp";
        depth_bits_per_pixel: u32 = 32, [8, 256], "bits/pixel", "depth+stencil bits stored per pixel",
            V2 "24-bit depth and 8-bit stencil in one 32-bit word";
        depth_write_buffer_entries: usize = 16, [1, 1 << 16], "writes", "depth writes buffered between depth test and memory port",
            I [4, 64] "not published; sized like the prefetch buffer it mirrors";
        fifo_depth_to_occu_entries: usize = 8, [1, 1 << 16], "fragments", "FIFO between depth test and Occlusion Unit",
            I [2, 32] "the paper's OccU sits after the depth test without a stated buffer; a short FIFO absorbs its k-cycle engines";
    }
    group occu: OccuArch; {
        memory_port_bits_per_cycle: u32 = 256, [32, 1 << 14], "bits/cycle", "the one main-memory port shared by depth reads and writes, colour writes, clears, OccU Control, the display refresh and the host",
            V "SGI O2 documents: a 256-bit word per 66 MHz cycle, up to 2.13 GB/s";
        memory_banks: u32 = 2, [1, 64], "banks", "memory banks, each with one open row; 64 KB tile p lies in bank p mod banks, and a depth read is a page hit when its bank's open row is its tile (1: one open row, the last read's)",
            I [1, 4] "SDRAM parts of the era had 2 (16 Mbit) or 4 (64 Mbit) internal banks; how the O2 spread its tiles over them is not published";
        colour_bits_per_pixel: u32 = 32, [0, 256], "bits/pixel", "colour written per drawn fragment (one that passes outside an occlusion render mode) and per cleared pixel (0: no colour traffic)",
            V "Linux gbefb.c: 32 bpp framebuffer tiles";
        blending: bool = false, "bool", "every drawn fragment blends: its colour is read (a read-modify-write) before it is written",
            I [false, true] "traces carry no blend state; opaque drawing is the common case, transparency blends";
        clear_writes_memory: bool = true, "bool", "a clear writes every depth and colour word of the viewport through the port (false: a free fast clear)",
            I [false, true] "no fast-clear tag memory is documented for the O2's rendering engine; unified memory is cleared by writing it";
        display_width_pixels: u32 = 1280, [0, 1 << 14], "pixels", "scanned-out display width; the display engine reads the framebuffer continuously (0: no refresh traffic)",
            V2 "O2 displays at 1280x1024";
        display_height_pixels: u32 = 1024, [0, 1 << 14], "pixels", "scanned-out display height",
            V2 "O2 displays at 1280x1024";
        display_bits_per_pixel: u32 = 32, [0, 256], "bits/pixel", "bits the display engine reads per displayed pixel",
            V2 "32 bpp true colour";
        display_refresh_hz: f64 = 75.0, [0.0, 1000.0], "Hz", "display refresh rate: the whole display is read this many times a second",
            V2 "O2 monitors at 72-76 Hz";
        host_memory_share: f64 = 0.05, [0.0, 0.9], "share", "fraction of the port's cycles the host CPU's own memory traffic takes (cache misses, I/O DMA)",
            I [0.0, 0.15] "not published; a CPU moving 100-300 MB/s of the 2.13 GB/s is 5-14 %";
        other_clients_slack_cycles: u32 = 16, [1, 1 << 16], "port cycles", "how far the display refresh and the host may fall behind their share before they take a port cycle from the pixel pipeline by force; until then they take the cycles it leaves idle",
            I [4, 64] "not published; the display engine's scan-out FIFO of a few hundred bytes to 2 KB (16 cycles: 512 bytes, 128 pixels at 32 bpp) and a few queued CPU misses";
        host_clock_mhz: f64 = 180.0, [0.001, 100_000.0], "MHz", "host CPU clock: the O2's R5000",
            V2 "O2 configurations: R5000 at 180-350 MHz, R10000 at 150-400 MHz";
        host_cycles_per_node: u64 = 200, [0, 1 << 24], "host cycles/node", "culling traversal per hierarchy node or grid cell visited",
            I [100, 1000] "a pointer chase and a loop over children, cache misses dominate";
        host_cycles_per_box_test: u64 = 120, [0, 1 << 24], "host cycles/box", "one bounding box tested against the view frustum",
            I [60, 300] "six planes against the box's nearest corner";
        host_cycles_per_decision: u64 = 20, [0, 1 << 24], "host cycles/decision", "one visibility decision taken from a query answer",
            I [10, 100] "a compare and a branch, a cache miss at most";
        host_cycles_per_draw: u64 = 2000, [0, 1 << 24], "host cycles/draw", "the GL driver's work per draw call: state validation and command setup",
            I [500, 10000] "GL drivers of the era spent a few to tens of microseconds a draw";
        host_cycles_per_state_change: u64 = 150, [0, 1 << 24], "host cycles/command", "the GL driver's work per state change, clear, or query begin or end",
            I [50, 500] "one register write through the driver and its validation";
        host_cycles_per_readback_pixel: u64 = 12, [0, 1 << 24], "host cycles/pixel", "reading back one framebuffer pixel from main memory and testing it for a change, the software occlusion test",
            I [5, 40] "a 32-bit read at the CPU's 100-300 MB/s from unified memory and a compare";
        geometry_host_cycles_per_vertex: u64 = 80, [0, 1 << 24], "host cycles/vertex", "software transform of one vertex on the host CPU: 4x4 transform, clip codes, divide, viewport",
            I [40, 200] "the O2's CPU does all vertex processing (V2); about one multiply-add a cycle";
        geometry_host_cycles_per_triangle: u64 = 120, [0, 1 << 24], "host cycles/triangle", "software setup of one submitted triangle on the host CPU before the rendering engine takes it",
            I [60, 300] "slopes and command packing, like a few vertices' work";
        result_notify_latency_cycles: u64 = 8, [0, 1 << 24], "cycles", "from a query's last record word in memory to the host seeing it: one uncached poll read",
            I [5, 20] "one uncached read of unified memory";
        result_read_cycles_per_word: u64 = 1, [0, 1 << 24], "cycles/word", "the host reading one result record word from main memory",
            I [1, 4] "cache-line reads at 2.13 GB/s";
    }
}

parameters! {
    /// The InfiniteReality-like machine's parameters, typed, each with its provenance (see
    /// `shared/reference/occlusion-unit.md`). Timing rules: [`crate::machines::ir`].
    pub struct IrArch {
        clock_mhz: f64 = 100.0, [0.001, 100_000.0], "MHz", "Raster Memory clock: one Fragment Generator / Image Engine cycle",
            I [75.0, 150.0] "not published per board; the Geometry Engines run at 90 MHz (V2), the raster chips of the era at 66-150 MHz";
        boards: usize = 4, [1, 4], "boards", "Raster Memory boards, each with one Fragment Generator",
            V2 "InfiniteReality configurations: 1, 2 or 4 Raster Memory boards";
        image_engines_per_board: usize = 80, [1, 1024], "Image Engines", "Image Engines per board, each owning its interleaved pixels' depth",
            V2 "20 Image Engine chips of 4 engines each per Raster Memory board";
        interleave: Interleave = Interleave::Columns, "name", "pixel -> Image Engine map: columns (x mod B*N), blocks (skewed 2D blocks) or morton",
            I [Interleave::Columns, Interleave::Morton] "the InfiniteReality's is not published; SGI's VGX interleaved columns (V), Morton order is the alternative ATTILA uses";
        block_width_pixels: u32 = 4, [1, 1 << 12], "pixels", "block width of the blocks and morton interleaves",
            I [2, 8] "not published; only the blocks and morton interleaves read it";
        block_height_pixels: u32 = 4, [1, 1 << 12], "pixels", "block height of the blocks and morton interleaves",
            I [2, 8] "not published; only the blocks and morton interleaves read it";
        fragment_generator_fragments_per_cycle: u32 = 2, [1, 1024], "fragments/cycle", "fragments one board's Fragment Generator emits per cycle",
            I [1, 4] "710 Mpixel/s over 4 boards at 100 MHz is 1.8 a board a cycle (V: Montrym 1997)";
        fragment_generator_setup_cycles: u64 = 4, [0, 1 << 20], "cycles/primitive", "cycles every Fragment Generator spends setting up each primitive",
            I [2, 16] "not published; edge and parameter slopes of one triangle";
        image_engine_cycles_per_fragment: u64 = 11, [1, 1 << 16], "cycles/fragment", "initiation interval of an Image Engine's pipelined depth stage: cycles between two fragments entering it",
            I [6, 23] "710 Mpixel/s textured and multisample-antialiased with 4 boards (V: Montrym 1997) is 177.5 Mpixel/s a board (1 board 177.5, 2 boards 355: the boards split the screen), 2.22 Mpixel/s an Image Engine, 45 cycles a pixel at 100 MHz; texturing is done before the Image Engines, and a depth test is one a sample, so at 4 samples a pixel a single-sample depth-only fragment takes 45 / 4 = 11; 8 to 2 samples give 6..23";
        image_engine_latency_cycles: u64 = 16, [1, 1 << 16], "cycles", "latency of an Image Engine's depth stage: from a fragment entering it to its result at the Occlusion Unit (fragments in flight: ceil(latency / interval))",
            I [11, 45] "a read, compare and write of the Image Engine's own SDRAM: at least one interval, at most the 45 cycles of a whole antialiased pixel";
        image_engine_fifo_entries: usize = 8, [1, 1 << 16], "fragments", "FIFO in front of each Image Engine; the Fragment Generator blocks while it is full",
            I [2, 32] "not published; a short on-chip FIFO";
    }
    group occu: OccuArch; {
        local_merge: MergeKind = MergeKind::Tree, "name", "stage one, the Image Engines of a board: reduction tree, daisy chain, or host reads",
            I [MergeKind::Tree, MergeKind::Chain] "the paper leaves hardware or software open; a tree is the fastest hardware, a chain the cheapest";
        local_merge_hop_latency_cycles: u64 = 2, [0, 1 << 20], "cycles", "tree or chain: cycles for one report to cross one hop",
            I [1, 8] "a register stage between neighbouring chips on one board";
        local_merge_read_latency_cycles: u64 = 40, [0, 1 << 20], "cycles", "software: cycles for the host to read one Image Engine's report",
            I [20, 100] "a PIO read on the board, 200-1000 ns";
        global_merge: MergeKind = MergeKind::Tree, "name", "stage two, the boards: reduction tree, daisy chain, or host reads",
            I [MergeKind::Tree, MergeKind::Chain] "the paper leaves hardware or software open; a tree is the fastest hardware, a chain the cheapest";
        global_merge_hop_latency_cycles: u64 = 8, [0, 1 << 20], "cycles", "tree or chain: cycles for one report to cross one board-to-board hop",
            I [4, 32] "a backplane crossing between boards, several board clocks";
        global_merge_read_latency_cycles: u64 = 100, [0, 1 << 20], "cycles", "software: cycles for the host to read one board's report over the bus",
            I [50, 500] "a PIO read over the system bus, 0.5-5 us";
        local_merge_link_bits_per_cycle: u64 = 32, [0, 1 << 20], "bits/cycle", "tree or chain: width of one link between a board's Image Engines; a partial report (8 words a tile, and verbose hits) crosses it word by word (0: unlimited)",
            I [16, 128] "not published; a 32-bit word a cycle between neighbouring Image Engine chips, as their memory buses move pixels";
        global_merge_link_bits_per_cycle: u64 = 64, [0, 1 << 20], "bits/cycle", "tree or chain: width of one board-to-board link the boards' merged reports cross word by word (0: unlimited)",
            I [32, 256] "not published; a backplane path of 400-3200 MB/s at the 100 MHz clock";
        report_dma_bits_per_cycle: u64 = 16, [0, 1 << 20], "bits/cycle", "after a hardware global merge: the final report written to host memory by DMA, this many bits a cycle (0: unlimited)",
            I [16, 32] "the host bus: 200 MB/s (Onyx, V2) to 400 MB/s (Onyx2, V2) at the 100 MHz clock";
        host_clock_mhz: f64 = 195.0, [0.001, 100_000.0], "MHz", "host CPU clock: an Onyx2's R10000",
            V2 "195 MHz R10000 Onyx2 systems";
        host_cycles_per_node: u64 = 200, [0, 1 << 24], "host cycles/node", "culling traversal per hierarchy node or grid cell visited",
            I [100, 1000] "a pointer chase and a loop over children";
        host_cycles_per_box_test: u64 = 120, [0, 1 << 24], "host cycles/box", "one bounding box tested against the view frustum",
            I [60, 300] "six planes against the box's nearest corner";
        host_cycles_per_decision: u64 = 20, [0, 1 << 24], "host cycles/decision", "one visibility decision taken from a query answer",
            I [10, 100] "a compare and a branch, a cache miss at most";
        host_cycles_per_draw: u64 = 2000, [0, 1 << 24], "host cycles/draw", "the GL driver's work per draw call",
            I [500, 10000] "GL drivers of the era spent a few to tens of microseconds a draw";
        host_cycles_per_state_change: u64 = 150, [0, 1 << 24], "host cycles/command", "the GL driver's work per state change, clear, or query begin or end",
            I [50, 500] "one command through the driver and its validation";
        host_cycles_per_readback_pixel: u64 = 40, [0, 1 << 24], "host cycles/pixel", "reading back one framebuffer pixel over the bus and testing it for a change, the software occlusion test",
            I [20, 100] "PIO reads from the raster boards";
        bus_megabytes_per_second: f64 = 200.0, [0.001, 1_000_000.0], "MB/s", "host-to-graphics bus the host writes vertices over",
            V2 "Onyx POWERpath-2 200 MB/s, Onyx2 400 MB/s";
        bus_bytes_per_vertex: u64 = 24, [0, 1 << 16], "bytes/vertex", "one vertex over the bus: position and normal as 32-bit floats",
            I [12, 48] "position alone to position, normal, colour and texture coordinates";
        geometry_engines: usize = 4, [1, 64], "engines", "Geometry Engines on the Geometry board, each taking whole batches",
            V2 "up to four Geometry Engines, MIMD";
        geometry_engine_clock_mhz: f64 = 90.0, [0.001, 100_000.0], "MHz", "Geometry Engine clock",
            V2 "Geometry Engines at 90 MHz";
        geometry_engine_cycles_per_vertex: u64 = 51, [0, 1 << 24], "GE cycles/vertex", "one Geometry Engine transforming and lighting one vertex",
            I [40, 80] "four engines at 90 MHz giving the 7 M lighted triangles/s of Montrym 1997 (V) at one new vertex a strip triangle; fewer lights or longer strips move it";
        geometry_engine_cycles_per_triangle: u64 = 10, [0, 1 << 24], "GE cycles/triangle", "one Geometry Engine assembling, clipping and setting up one submitted triangle",
            I [5, 40] "not published; a few instructions a triangle beside the vertices' work";
        result_notify_latency_cycles: u64 = 100, [0, 1 << 24], "cycles", "from a query's result at the global merge to the host seeing it: an interrupt or a poll over the bus",
            I [50, 500] "about 1 us, 0.5-5 us for an interrupt or a poll";
        result_read_cycles_per_word: u64 = 10, [0, 1 << 24], "cycles/word", "the host reading one result record word over the bus",
            I [5, 50] "50-500 ns PIO reads";
    }
}

/// The O2-like machine's documented table ([`O2Arch`]'s declaration).
pub static O2_PARAMS: LazyLock<Vec<Param>> = LazyLock::new(O2Arch::table);
/// The InfiniteReality-like machine's documented table ([`IrArch`]'s declaration).
pub static IR_PARAMS: LazyLock<Vec<Param>> = LazyLock::new(IrArch::table);

/// Names of the interleaves (see [`Interleave`]).
pub const INTERLEAVES: &[&str] = &["columns", "blocks", "morton"];
/// Names of the merge networks (see [`MergeKind`]).
pub const MERGE_KINDS: &[&str] = &["tree", "chain", "software"];

/// Machines that have a parameter table.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Machine {
    O2,
    Ir,
}

impl Machine {
    pub const ALL: [Machine; 2] = [Machine::O2, Machine::Ir];

    pub fn name(self) -> &'static str {
        match self {
            Machine::O2 => "o2",
            Machine::Ir => "ir",
        }
    }

    pub fn params(self) -> &'static [Param] {
        match self {
            Machine::O2 => O2_PARAMS.as_slice(),
            Machine::Ir => IR_PARAMS.as_slice(),
        }
    }

    pub fn title(self) -> &'static str {
        match self {
            Machine::O2 => "O2-like: one rasterizer, one pixel pipeline, unified memory",
            Machine::Ir => "InfiniteReality-like: Raster Memory boards of Image Engines, an OccU at each, two-stage merge",
        }
    }

    fn from_name(name: &str) -> Option<Machine> {
        Machine::ALL.into_iter().find(|m| m.name() == name)
    }
}

#[derive(Debug, Error, PartialEq)]
pub enum ArchError {
    #[error("unknown architecture '{name}' (built-in: {known})")]
    UnknownBuiltin { name: String, known: String },
    #[error("architecture file: {0}")]
    Toml(String),
    #[error("architecture file: missing `machine = \"...\"` (known machines: {0})")]
    MissingMachine(String),
    #[error("unknown machine '{name}' (known machines: {known})")]
    UnknownMachine { name: String, known: String },
    #[error("unknown parameter '{key}'{hint}")]
    UnknownKey { key: String, hint: String },
    /// A table in an architecture file other than its machine's section.
    #[error("[{section}] is no section of an {machine} architecture (it has `machine` and one [{machine}] section){hint}")]
    UnknownSection {
        section: String,
        machine: &'static str,
        hint: String,
    },
    #[error("parameter '{key}' = {value}: expected {expected}")]
    BadValue {
        key: String,
        value: String,
        expected: String,
    },
    #[error("expected key=value, got '{0}'")]
    BadAssignment(String),
    #[error("impossible configuration: {0}")]
    Impossible(String),
    #[error("line {line}: {error}")]
    AtLine { line: usize, error: Box<ArchError> },
}

/// A resolved architecture: a machine and a value for each of its parameters.
#[derive(Clone, Debug, PartialEq)]
pub struct Arch {
    machine: Machine,
    /// Parallel to `machine.params()`.
    values: Vec<Value>,
}

/// Names of the built-in architectures.
pub const BUILTIN_ARCHS: &[&str] = &["o2", "ir", "ir1", "ir2", "ir4"];

impl Arch {
    /// The machine's defaults.
    pub fn defaults(machine: Machine) -> Arch {
        Arch {
            machine,
            values: machine.params().iter().map(|p| p.default).collect(),
        }
    }

    /// A built-in architecture by name.
    pub fn builtin(name: &str) -> Result<Arch, ArchError> {
        match name {
            "o2" => Ok(Arch::defaults(Machine::O2)),
            // `ir` is the InfiniteReality-like machine at its defaults (4 boards), the base a
            // sweep over `boards` starts from.
            "ir" => Ok(Arch::defaults(Machine::Ir)),
            "ir1" | "ir2" | "ir4" => {
                let mut arch = Arch::defaults(Machine::Ir);
                arch.set_value("boards", &name[2..])?;
                Ok(arch)
            }
            _ => Err(ArchError::UnknownBuiltin {
                name: name.to_string(),
                known: BUILTIN_ARCHS.join(", "),
            }),
        }
    }

    /// Parse an architecture file. Parameters it leaves out keep their defaults.
    pub fn from_toml(text: &str) -> Result<Arch, ArchError> {
        let table: toml::Table = text
            .parse()
            .map_err(|e: toml::de::Error| ArchError::Toml(e.to_string()))?;
        let machines = || Machine::ALL.map(|m| m.name()).join(", ");
        let machine = match table.get("machine") {
            None => return Err(ArchError::MissingMachine(machines())),
            Some(toml::Value::String(name)) => {
                Machine::from_name(name).ok_or_else(|| ArchError::UnknownMachine {
                    name: name.clone(),
                    known: machines(),
                })?
            }
            Some(other) => {
                return Err(ArchError::BadValue {
                    key: "machine".into(),
                    value: other.to_string(),
                    expected: format!("a string naming a machine ({})", machines()),
                })
            }
        };
        let mut arch = Arch::defaults(machine);
        for (key, value) in &table {
            match (key.as_str(), value) {
                ("machine", _) => {}
                (section, toml::Value::Table(entries)) if section == machine.name() => {
                    for (name, value) in entries {
                        let at_line = |error| match line_of_key(text, name) {
                            0 => error,
                            line => ArchError::AtLine {
                                line,
                                error: Box::new(error),
                            },
                        };
                        let parsed = arch.toml_value(name, value).map_err(at_line)?;
                        let index = arch.index(name).map_err(at_line)?;
                        arch.values[index] = parsed;
                    }
                }
                (section, value) => {
                    let error = match value {
                        toml::Value::Table(_) => ArchError::UnknownSection {
                            section: section.to_owned(),
                            machine: machine.name(),
                            // The section of another machine: the file names the wrong one.
                            hint: Machine::from_name(section).map_or(String::new(), |_| {
                                format!(": [{section}] is the {section} machine's")
                            }),
                        },
                        _ => ArchError::UnknownKey {
                            key: key.clone(),
                            hint: format!(
                                " at top level (expected `machine` and a [{}] section)",
                                machine.name()
                            ),
                        },
                    };
                    return Err(match line_of_key(text, section) {
                        0 => error,
                        line => ArchError::AtLine {
                            line,
                            error: Box::new(error),
                        },
                    });
                }
            }
        }
        arch.check()?;
        Ok(arch)
    }

    pub fn machine(&self) -> Machine {
        self.machine
    }

    /// Apply one `key=value` override (key with or without the `machine.` prefix).
    pub fn set(&mut self, assignment: &str) -> Result<(), ArchError> {
        let (key, value) = assignment
            .split_once('=')
            .filter(|(key, _)| !key.trim().is_empty())
            .ok_or_else(|| ArchError::BadAssignment(assignment.to_string()))?;
        self.set_value(key.trim(), value.trim())
    }

    /// Set one parameter from its text form; the whole configuration is re-checked.
    pub fn set_value(&mut self, key: &str, value: &str) -> Result<(), ArchError> {
        let prefix = format!("{}.", self.machine.name());
        let key = key.strip_prefix(&prefix).unwrap_or(key);
        let parsed = self.parse_value(key, value)?;
        let index = self.index(key)?;
        let old = std::mem::replace(&mut self.values[index], parsed);
        if let Err(e) = self.check() {
            self.values[index] = old;
            return Err(e);
        }
        Ok(())
    }

    /// A parameter's value by key.
    pub fn get(&self, key: &str) -> Option<Value> {
        self.index(key).ok().map(|i| self.values[i])
    }

    /// `(key, value)` for every parameter, in table order.
    /// Every parameter with its value and unit, as reports and sweep records carry them.
    pub fn report_entries(&self) -> Vec<ArchEntry> {
        self.entries()
            .map(|(param, value)| ArchEntry {
                key: param.key.to_string(),
                value,
                unit: param.unit.to_string(),
            })
            .collect()
    }

    pub fn entries(&self) -> impl Iterator<Item = (&'static Param, Value)> + '_ {
        self.machine
            .params()
            .iter()
            .zip(self.values.iter().copied())
    }

    /// The architecture as a TOML file with every parameter's unit and meaning as a comment;
    /// it reads back as the same architecture.
    pub fn to_documented_toml(&self) -> String {
        let mut out = String::new();
        let _ = writeln!(out, "# {}", self.machine.title());
        let _ = writeln!(
            out,
            "machine = \"{}\"\n\n[{}]",
            self.machine.name(),
            self.machine.name()
        );
        let width = self
            .entries()
            .map(|(p, v)| p.key.len() + v.to_string().len())
            .max()
            .unwrap_or(0);
        for (param, value) in self.entries() {
            let assignment = format!("{} = {}", param.key, value);
            let _ = writeln!(
                out,
                "{assignment:<w$}  # [{}] {} ({})",
                param.unit,
                param.meaning,
                param.provenance,
                w = width + 3
            );
        }
        out
    }

    /// The O2-like machine's typed parameters.
    pub fn o2(&self) -> Result<O2Arch, ArchError> {
        if self.machine != Machine::O2 {
            return Err(ArchError::Impossible(format!(
                "the '{}' machine is not the O2-like machine",
                self.machine.name()
            )));
        }
        let arch = O2Arch::from_cursor(&mut Cursor::new(&self.values));
        arch.check()?;
        Ok(arch)
    }

    /// The InfiniteReality-like machine's typed parameters.
    pub fn ir(&self) -> Result<IrArch, ArchError> {
        if self.machine != Machine::Ir {
            return Err(ArchError::Impossible(format!(
                "the '{}' machine is not the InfiniteReality-like machine",
                self.machine.name()
            )));
        }
        let arch = IrArch::from_cursor(&mut Cursor::new(&self.values));
        arch.check()?;
        Ok(arch)
    }

    fn check(&self) -> Result<(), ArchError> {
        match self.machine {
            Machine::O2 => self.o2().map(|_| ()),
            Machine::Ir => self.ir().map(|_| ()),
        }
    }

    fn index(&self, key: &str) -> Result<usize, ArchError> {
        let params = self.machine.params();
        params
            .iter()
            .position(|p| p.key == key)
            .ok_or_else(|| ArchError::UnknownKey {
                key: key.to_string(),
                hint: close_keys_hint(key, params),
            })
    }

    /// A TOML value for `key`: of the TOML type the parameter's kind is written in (a
    /// number for numbers, `true`/`false` for flags, a string for names), then checked as
    /// `--set` text is.
    fn toml_value(&self, key: &str, value: &toml::Value) -> Result<Value, ArchError> {
        let param = &self.machine.params()[self.index(key)?];
        let fits = matches!(
            (param.kind, value),
            (
                ParamKind::Float { .. },
                toml::Value::Float(_) | toml::Value::Integer(_)
            ) | (ParamKind::Int { .. }, toml::Value::Integer(_))
                | (ParamKind::Bool, toml::Value::Boolean(_))
                | (ParamKind::Choice { .. }, toml::Value::String(_))
        );
        if !fits {
            return Err(ArchError::BadValue {
                key: key.to_string(),
                value: format!("{value} (a TOML {})", value.type_str()),
                expected: param.kind.describe(),
            });
        }
        let text = match value {
            toml::Value::String(s) => s.clone(),
            other => other.to_string(),
        };
        self.parse_value(key, &text)
    }

    fn parse_value(&self, key: &str, text: &str) -> Result<Value, ArchError> {
        let param = &self.machine.params()[self.index(key)?];
        let bad = || ArchError::BadValue {
            key: key.to_string(),
            value: text.to_string(),
            expected: param.kind.describe(),
        };
        let value = match param.kind {
            ParamKind::Float { min, max } => {
                let v: f64 = text.parse().map_err(|_| bad())?;
                if !(min..=max).contains(&v) {
                    return Err(bad());
                }
                Value::Float(v)
            }
            ParamKind::Int { min, max } => {
                let v: u64 = text.parse().map_err(|_| bad())?;
                if !(min..=max).contains(&v) {
                    return Err(bad());
                }
                Value::Int(v)
            }
            ParamKind::Bool => Value::Bool(text.parse().map_err(|_| bad())?),
            ParamKind::Choice { choices } => Value::Choice(
                choices
                    .iter()
                    .copied()
                    .find(|c| *c == text.trim_matches('"'))
                    .ok_or_else(bad)?,
            ),
        };
        Ok(value)
    }
}

/// The 1-based line where `key` is assigned in a TOML text, at the start of a line or inside
/// an inline table, or opens a table (`[o2.key]`, which had been named with no line; 0 when
/// not found).
fn line_of_key(text: &str, key: &str) -> usize {
    let assigns = |line: &str| {
        line.match_indices(key).any(|(at, _)| {
            let before = line[..at].chars().next_back();
            let word_start = before.is_none_or(|c| !(c.is_alphanumeric() || c == '_'));
            word_start && line[at + key.len()..].trim_start().starts_with('=')
        })
    };
    let opens = |line: &str| {
        let header = line.trim().trim_start_matches('[');
        let header = header.split(']').next().unwrap_or_default();
        line.trim().starts_with('[') && header.rsplit('.').next().map(str::trim) == Some(key)
    };
    let names = |line: &str| assigns(line) || opens(line);
    text.lines().position(names).map_or(0, |index| index + 1)
}

/// " (did you mean a, b?)" for the keys close to `key`, or the list of all keys.
fn close_keys_hint(key: &str, params: &[Param]) -> String {
    let close: Vec<&str> = params
        .iter()
        .map(|p| p.key)
        .filter(|k| {
            edit_distance(k, key) <= 3 || k.contains(key) || (key.len() >= 4 && key.contains(k))
        })
        .collect();
    if close.is_empty() {
        let all: Vec<&str> = params.iter().map(|p| p.key).collect();
        format!(" (known: {})", all.join(", "))
    } else {
        format!(" (did you mean {}?)", close.join(", "))
    }
}

fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut diagonal = row[0];
        row[0] = i + 1;
        for (j, &cb) in b.iter().enumerate() {
            let substitution = diagonal + (ca != cb) as usize;
            diagonal = row[j + 1];
            row[j + 1] = substitution.min(row[j] + 1).min(row[j + 1] + 1);
        }
    }
    row[b.len()]
}

/// Bits of one OccU Control word (a record entry or a hit).
pub const OCCU_WORD_BITS: u32 = 32;

impl Arch {
    /// The machine's pipeline clock.
    pub fn clock_mhz(&self) -> Result<f64, ArchError> {
        Ok(match self.machine() {
            Machine::O2 => self.o2()?.clock_mhz,
            Machine::Ir => self.ir()?.clock_mhz,
        })
    }
}

impl O2Arch {
    /// Cross-parameter rules the per-key ranges cannot express.
    fn check(&self) -> Result<(), ArchError> {
        let port = self.memory_port_bits_per_cycle;
        if !port.is_multiple_of(self.depth_bits_per_pixel) {
            return Err(ArchError::Impossible(format!(
                "memory_port_bits_per_cycle ({port}) must be a multiple of depth_bits_per_pixel ({})",
                self.depth_bits_per_pixel
            )));
        }
        if !port.is_multiple_of(OCCU_WORD_BITS) {
            return Err(ArchError::Impossible(format!(
                "memory_port_bits_per_cycle ({port}) must be a multiple of the {OCCU_WORD_BITS}-bit OccU word"
            )));
        }
        let reserved = self.reserved_port_share();
        if reserved > 0.9 {
            return Err(ArchError::Impossible(format!(
                "the display refresh ({:.1} % of the memory port) and host_memory_share ({:.1} %) leave the pixel pipeline {:.1} %; at most 90 % may be reserved (a display_refresh_hz of 0 turns the refresh off)",
                100.0 * self.refresh_share(),
                100.0 * self.host_memory_share,
                100.0 * (1.0 - reserved)
            )));
        }
        if self.depth_bits_per_pixel + self.colour_bits_per_pixel > port {
            return Err(ArchError::Impossible(format!(
                "depth_bits_per_pixel + colour_bits_per_pixel ({}) must fit the memory port ({port} bits)",
                self.depth_bits_per_pixel + self.colour_bits_per_pixel
            )));
        }
        if !self
            .framebuffer_tile_width_pixels
            .is_multiple_of(self.pixels_per_word())
        {
            return Err(ArchError::Impossible(format!(
                "framebuffer_tile_width_pixels ({}) must be a multiple of the {} pixels in one memory word",
                self.framebuffer_tile_width_pixels,
                self.pixels_per_word()
            )));
        }
        Ok(())
    }

    /// The share of port cycles the display refresh takes: the bits it reads a second over
    /// the bits the port moves a second.
    pub fn refresh_share(&self) -> f64 {
        let bits_per_second = self.display_width_pixels as f64
            * self.display_height_pixels as f64
            * self.display_bits_per_pixel as f64
            * self.display_refresh_hz;
        bits_per_second / (self.memory_port_bits_per_cycle as f64 * self.clock_mhz * 1e6)
    }

    /// The share of port cycles taken before the pixel pipeline's requests: the display
    /// refresh's and the host's ([`crate::blocks::memory_port`]).
    pub fn reserved_port_share(&self) -> f64 {
        self.refresh_share() + self.host_memory_share
    }

    /// Depth pixels in one memory word.
    pub fn pixels_per_word(&self) -> u32 {
        self.memory_port_bits_per_cycle / self.depth_bits_per_pixel
    }

    /// Where a depth pixel lives: the framebuffer tiles, words and banks of the depth buffer.
    pub fn depth_layout(&self) -> DepthLayout {
        DepthLayout {
            tile_width_pixels: self.framebuffer_tile_width_pixels,
            tile_height_pixels: self.framebuffer_tile_height_pixels,
            pixels_per_word: self.pixels_per_word(),
            banks: self.memory_banks,
        }
    }

    /// Largest counter value: 2^counter_bits - 1.
    pub fn counter_max(&self) -> u64 {
        self.occu.counter_max()
    }
}

impl OccuArch {
    /// Largest counter value: 2^counter_bits - 1.
    pub fn counter_max(&self) -> u64 {
        u64::MAX >> (64 - self.counter_bits)
    }
}

/// How pixels are dealt to the Image Engines of all boards (`U = boards x
/// image_engines_per_board` units; unit `g` is Image Engine `g / boards` of board `g mod
/// boards`, so neighbouring units sit on different boards).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Interleave {
    /// Column `x` belongs to unit `x mod U` (the default: SGI's VGX interleaved columns, and
    /// the InfiniteReality interleave is not published).
    Columns,
    /// Blocks of `block_width x block_height` pixels; block `(bx, by)` belongs to unit
    /// `(bx + by) mod U` (skewed, so a column of blocks also cycles through the units).
    Blocks,
    /// Blocks numbered in Morton (Z) order of `(bx, by)`; block `m` belongs to unit `m mod U`.
    Morton,
}

impl Named for Interleave {
    const ALL: &'static [Interleave] =
        &[Interleave::Columns, Interleave::Blocks, Interleave::Morton];
    const NAMES: &'static [&'static str] = INTERLEAVES;
}

/// How one merge stage combines its inputs' reports.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MergeKind {
    /// A binary reduction tree: each hop costs `hop_latency_cycles`.
    Tree,
    /// A daisy chain through the inputs in order: each hop costs `hop_latency_cycles`.
    Chain,
    /// The host reads every input's report over the bus, one at a time, each read costing
    /// `read_latency_cycles`.
    Software,
}

impl Named for MergeKind {
    const ALL: &'static [MergeKind] = &[MergeKind::Tree, MergeKind::Chain, MergeKind::Software];
    const NAMES: &'static [&'static str] = MERGE_KINDS;
}

impl MergeKind {
    pub fn name(self) -> &'static str {
        match self {
            MergeKind::Tree => "tree",
            MergeKind::Chain => "chain",
            MergeKind::Software => "software",
        }
    }
}

/// One merge stage's network, latencies and link width.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MergeNetwork {
    pub kind: MergeKind,
    pub hop_latency_cycles: u64,
    pub read_latency_cycles: u64,
    /// Tree or chain: bits one link moves a cycle (0: unlimited).
    pub link_bits_per_cycle: u64,
    /// Software: cycles the host takes to read one word of a report over the bus.
    pub read_cycles_per_word: u64,
}

impl IrArch {
    /// Cross-parameter rules the per-key ranges cannot express.
    fn check(&self) -> Result<(), ArchError> {
        if ![1, 2, 4].contains(&self.boards) {
            return Err(ArchError::Impossible(format!(
                "boards ({}) must be 1, 2 or 4",
                self.boards
            )));
        }
        Ok(())
    }

    /// Fragments in flight in an Image Engine's depth stage: `ceil(latency / interval)`, at
    /// least one (a latency below the interval is one unpipelined fragment at a time).
    pub fn image_engine_in_flight(&self) -> usize {
        self.image_engine_latency_cycles
            .div_ceil(self.image_engine_cycles_per_fragment)
            .max(1) as usize
    }

    /// Image Engines on all boards.
    pub fn image_engines(&self) -> usize {
        self.boards * self.image_engines_per_board
    }

    /// Largest counter value: 2^counter_bits - 1.
    pub fn counter_max(&self) -> u64 {
        self.occu.counter_max()
    }

    /// Stage one's network: the Image Engines of a board.
    pub fn local_merge_network(&self) -> MergeNetwork {
        MergeNetwork {
            kind: self.local_merge,
            hop_latency_cycles: self.local_merge_hop_latency_cycles,
            read_latency_cycles: self.local_merge_read_latency_cycles,
            link_bits_per_cycle: self.local_merge_link_bits_per_cycle,
            read_cycles_per_word: self.result_read_cycles_per_word,
        }
    }

    /// Stage two's network: the boards.
    pub fn global_merge_network(&self) -> MergeNetwork {
        MergeNetwork {
            kind: self.global_merge,
            hop_latency_cycles: self.global_merge_hop_latency_cycles,
            read_latency_cycles: self.global_merge_read_latency_cycles,
            link_bits_per_cycle: self.global_merge_link_bits_per_cycle,
            read_cycles_per_word: self.result_read_cycles_per_word,
        }
    }
}
