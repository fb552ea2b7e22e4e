//! The one waveform writer: signals declared in scopes, values given in blocks, and the
//! change detection every format shares; what a format writes is its [`WaveEncoder`]
//! ([`crate::vcd::VcdEncoder`], [`crate::fst::FstEncoder`], or several at once: an
//! `Option` of an encoder is one that may be absent, a pair is both).
//!
//! An encoder is told only what changed: a signal's value (masked to its width) when it
//! differs from the one last given, or its first value, each after the time it happens at
//! (told once per time, before its first change). Times must not go back.
//!
//! Speed (a whole-run dump is dominated by this writer): signals are given in blocks
//! ([`WaveWriter::change_block`], `N` consecutive signals, `N <= 64`). Inlined into the
//! caller, a block is one unrolled, branch-free compare of the values (still in registers,
//! unmasked) with those last given, gathering a bit per difference; the set bits alone are
//! visited, and the encoder hears of the block's end once ([`WaveEncoder::block_end`]).

use crate::bits::mask;
use std::io;

/// Most signals in a block.
pub const BLOCK_SIGNALS: usize = 64;

/// Declared kind of a signal.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VarKind {
    Wire,
    Reg,
}

/// Handle of a declared signal: signals are numbered from 0 in declaration order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SignalId(pub usize);

/// A waveform format: what to write for a declaration, a time and a change.
pub trait WaveEncoder {
    /// What [`WaveEncoder::finish`] hands back (the destination, say).
    type Output;
    fn scope(&mut self, name: &str);
    fn upscope(&mut self);
    /// Declare the next signal (its id is the count declared before it).
    fn var(&mut self, kind: VarKind, name: &str, width: u32);
    fn end_definitions(&mut self);
    /// The changes that follow happen at `time` (ps), later than any time told before.
    fn time(&mut self, time: u64);
    /// Signal `id` holds `value` (already masked to its width) from the current time on.
    fn value(&mut self, id: usize, value: u64);
    /// A block's changes are done (a buffered encoder may write out here).
    #[inline(always)]
    fn block_end(&mut self) {}
    /// The dump ends at `time`, later than any time told before.
    fn end_at(&mut self, time: u64);
    /// Write out everything; the first error, if any.
    fn finish(self) -> io::Result<Self::Output>;
}

/// An encoder that may be absent: then nothing is written.
impl<E: WaveEncoder> WaveEncoder for Option<E> {
    type Output = Option<E::Output>;
    fn scope(&mut self, name: &str) {
        if let Some(e) = self {
            e.scope(name);
        }
    }
    fn upscope(&mut self) {
        if let Some(e) = self {
            e.upscope();
        }
    }
    fn var(&mut self, kind: VarKind, name: &str, width: u32) {
        if let Some(e) = self {
            e.var(kind, name, width);
        }
    }
    fn end_definitions(&mut self) {
        if let Some(e) = self {
            e.end_definitions();
        }
    }
    #[inline(always)]
    fn time(&mut self, time: u64) {
        if let Some(e) = self {
            e.time(time);
        }
    }
    #[inline(always)]
    fn value(&mut self, id: usize, value: u64) {
        if let Some(e) = self {
            e.value(id, value);
        }
    }
    #[inline(always)]
    fn block_end(&mut self) {
        if let Some(e) = self {
            e.block_end();
        }
    }
    fn end_at(&mut self, time: u64) {
        if let Some(e) = self {
            e.end_at(time);
        }
    }
    fn finish(self) -> io::Result<Self::Output> {
        self.map(WaveEncoder::finish).transpose()
    }
}

/// Two encoders fed the same changes.
impl<A: WaveEncoder, B: WaveEncoder> WaveEncoder for (A, B) {
    type Output = (A::Output, B::Output);
    fn scope(&mut self, name: &str) {
        self.0.scope(name);
        self.1.scope(name);
    }
    fn upscope(&mut self) {
        self.0.upscope();
        self.1.upscope();
    }
    fn var(&mut self, kind: VarKind, name: &str, width: u32) {
        self.0.var(kind, name, width);
        self.1.var(kind, name, width);
    }
    fn end_definitions(&mut self) {
        self.0.end_definitions();
        self.1.end_definitions();
    }
    #[inline(always)]
    fn time(&mut self, time: u64) {
        self.0.time(time);
        self.1.time(time);
    }
    #[inline(always)]
    fn value(&mut self, id: usize, value: u64) {
        self.0.value(id, value);
        self.1.value(id, value);
    }
    #[inline(always)]
    fn block_end(&mut self) {
        self.0.block_end();
        self.1.block_end();
    }
    fn end_at(&mut self, time: u64) {
        self.0.end_at(time);
        self.1.end_at(time);
    }
    /// Both are finished; the first one's error wins.
    fn finish(self) -> io::Result<Self::Output> {
        let (a, b) = (self.0.finish(), self.1.finish());
        Ok((a?, b?))
    }
}

/// Declarations, change detection and time keeping in front of an encoder.
pub struct WaveWriter<E> {
    encoder: E,
    /// Per signal, by id: the value last given (unmasked, so the compare needs no mask;
    /// its masked bits are those last written, once written).
    given: Vec<u64>,
    /// Per signal, by id: all ones in its width.
    masks: Vec<u64>,
    /// A bit per signal with no value written yet (a 64-bit signal has no spare value for
    /// a sentinel).
    unwritten: Vec<u64>,
    /// Signals with no value written yet.
    unwritten_count: usize,
    defining: bool,
    /// The current time.
    time: u64,
    /// `time` is not yet told: the next change tells it first.
    pending: bool,
    /// The last time told.
    written: Option<u64>,
}

impl<E: WaveEncoder> WaveWriter<E> {
    pub fn with_encoder(encoder: E) -> WaveWriter<E> {
        WaveWriter {
            encoder,
            given: Vec::new(),
            masks: Vec::new(),
            unwritten: Vec::new(),
            unwritten_count: 0,
            defining: true,
            time: 0,
            pending: true,
            written: None,
        }
    }

    pub fn encoder(&self) -> &E {
        &self.encoder
    }

    pub fn scope(&mut self, name: &str) {
        debug_assert!(self.defining);
        self.encoder.scope(name);
    }

    pub fn upscope(&mut self) {
        self.encoder.upscope();
    }

    /// Declare a signal `width` bits wide (1..=64).
    pub fn var(&mut self, kind: VarKind, name: &str, width: u32) -> SignalId {
        assert!(self.defining && (1..=64).contains(&width));
        let id = self.given.len();
        self.encoder.var(kind, name, width);
        self.given.push(0);
        self.masks.push(mask(width));
        // Room for a block's bits to be read as two words from any signal on.
        self.unwritten.resize(id / 64 + 2, 0);
        self.unwritten[id / 64] |= 1 << (id % 64);
        self.unwritten_count += 1;
        SignalId(id)
    }

    pub fn end_definitions(&mut self) {
        self.encoder.end_definitions();
        self.defining = false;
    }

    /// Following changes happen at `time` (ps), which must not go back.
    #[inline]
    pub fn set_time(&mut self, time: u64) {
        debug_assert!(!self.defining);
        debug_assert!(self.written.is_none_or(|t| time >= t));
        self.time = time;
        self.pending = self.written != Some(time);
    }

    /// The signal holds `value` (masked to its width) from the current time on.
    #[inline]
    pub fn change(&mut self, id: SignalId, value: u64) {
        self.change_block(id, &[value]);
    }

    /// Signals `first .. first + N` (N <= 64) hold `values` (each masked to its width) from
    /// the current time on; the encoder hears of them in signal order. Inlined into the
    /// caller, a block is one unrolled, branch-free compare of the values (still in
    /// registers) with those last given, gathering a bit per difference; only a block with
    /// a difference goes on, visiting the set bits.
    #[inline(always)]
    pub fn change_block<const N: usize>(&mut self, first: SignalId, values: &[u64; N]) {
        const { assert!(N <= BLOCK_SIGNALS, "a block has at most 64 signals") };
        let given: &[u64; N] = (&self.given[first.0..first.0 + N])
            .try_into()
            .expect("a slice of N");
        let mut changed = 0u64;
        for bit in 0..N {
            changed |= ((values[bit] != given[bit]) as u64) << bit;
        }
        let unwritten = if self.unwritten_count != 0 {
            self.unwritten_in(first.0, N)
        } else {
            0
        };
        changed |= unwritten;
        if changed != 0 {
            self.write_changed(first.0, values, changed, unwritten);
        }
    }

    /// A bit per signal of `first .. first + count` (count <= 64) with no value written yet.
    #[cold]
    fn unwritten_in(&self, first: usize, count: usize) -> u64 {
        let (word, shift) = (first / 64, first % 64);
        let low = self.unwritten[word] >> shift;
        let high = (self.unwritten[word + 1] << 1) << (63 - shift);
        (low | high) & mask(count as u32)
    }

    /// Take the values of signals `first + i` for the bits `i` set in `changed`, telling
    /// the encoder those whose masked value changed or, for the bits set in `unwritten`,
    /// their first value (after the pending time, if any).
    #[inline(always)]
    fn write_changed(&mut self, first: usize, values: &[u64], mut changed: u64, unwritten: u64) {
        let given = &mut self.given[first..first + values.len()];
        let masks = &self.masks[first..first + values.len()];
        while changed != 0 {
            let offset = changed.trailing_zeros() as usize;
            changed &= changed - 1;
            let value = values[offset];
            let old = std::mem::replace(&mut given[offset], value);
            let mask = masks[offset];
            let first_value = (unwritten >> offset) & 1 != 0;
            if (old ^ value) & mask != 0 || first_value {
                if first_value {
                    let id = first + offset;
                    self.unwritten[id / 64] &= !(1 << (id % 64));
                    self.unwritten_count -= 1;
                }
                if self.pending {
                    self.encoder.time(self.time);
                    self.written = Some(self.time);
                    self.pending = false;
                }
                self.encoder.value(first + offset, value & mask);
            }
        }
        self.encoder.block_end();
    }

    /// A last time `time` (if later than every change) so that viewers show the dump up to
    /// it.
    pub fn end_at(&mut self, time: u64) {
        if self.written.is_none_or(|t| time > t) {
            self.encoder.end_at(time);
            self.written = Some(time);
            self.pending = false;
        }
    }

    /// Write out everything: the encoder's output, or the first error.
    pub fn finish(self) -> io::Result<E::Output> {
        self.encoder.finish()
    }
}
