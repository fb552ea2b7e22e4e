//! A small Value Change Dump (IEEE 1364 §18) encoder behind the shared
//! [`crate::wave::WaveWriter`] (which does the change detection): lines gathered into 64 KiB
//! writes to its destination.
//!
//! Format: `$version`, `$timescale 1ps`, nested `$scope module NAME $end` with
//! `$var wire|reg WIDTH CODE NAME $end`, `$enddefinitions $end`; then `#TIME` lines (strictly
//! increasing, written only when some value changed at that time) each followed by the
//! changes: `0C`/`1C` for 1-bit signals, `bVALUE CODE` (binary, no leading zeros) for wider
//! ones. A signal's first value is written the first time it is given, changed or not.
//! Identifier codes are printable ASCII 33..=126 in base 94.
//!
//! Speed: a changed value is formatted into a fixed buffer whose slack past its spill mark
//! holds a whole block (checked once per block, at [`WaveEncoder::block_end`]), so the
//! formatter writes whole groups (8 binary digits per table entry, 4 groups for signals up to
//! 32 bits and 8 above, then the pre-encoded 16-byte ` CODE\n` tail; a 1-bit line is the same
//! with no `b`) and advances by the bytes that count: no per-bit loop, no variable-length
//! copy, no bounds checks. A timestamp's digits above its last 8 are kept from the one before
//! (they change every 10^8 ps, 6,667 cycles at 66.67 MHz); the last 8 come from a 100-entry
//! pair table.

use crate::bits::mask;
use crate::wave::{WaveEncoder, WaveWriter, BLOCK_SIGNALS};
use std::io::{self, Write};

pub use crate::wave::{SignalId, VarKind};

/// Bytes gathered before one write to the destination.
const BUFFER_BYTES: usize = 1 << 16;
/// Bytes one line's writes may touch: a value line's whole groups (`b`, 64 digits, a
/// 16-byte tail: 81) or a timestamp line (`#`, 20 digits, newline: 22).
const LINE_SCRATCH: usize = 128;
/// Room past the spill mark: a timestamp line and then a whole block's lines fit in it, so
/// the buffer is checked once per block, not once per line.
const SLACK_BYTES: usize = (BLOCK_SIGNALS + 1) * LINE_SCRATCH;
/// A timestamp's last 8 digits are formatted every time; those above them are kept.
const LOW_DIGITS_RANGE: u64 = 100_000_000;

/// The ASCII binary digits of every byte value, most significant bit first.
const BINARY_DIGITS: [[u8; 8]; 256] = {
    let mut table = [[0u8; 8]; 256];
    let mut value = 0;
    while value < 256 {
        let mut bit = 0;
        while bit < 8 {
            table[value][bit] = b'0' + ((value >> (7 - bit)) & 1) as u8;
            bit += 1;
        }
        value += 1;
    }
    table
};

/// Two ASCII decimal digits of every value 0..100.
const DECIMAL_PAIRS: [[u8; 2]; 100] = {
    let mut table = [[0u8; 2]; 100];
    let mut value = 0;
    while value < 100 {
        table[value] = [b'0' + (value / 10) as u8, b'0' + (value % 10) as u8];
        value += 1;
    }
    table
};

/// What the writer keeps of one signal besides the value last given, read when a compare
/// found it changed.
struct Signal {
    /// All ones in the signal's width.
    mask: u64,
    /// What follows the value: ` CODE\n` (`CODE\n` for a 1-bit signal), zero padded.
    tail: [u8; 16],
    tail_len: u8,
    /// Bytes before the digits: 1 (`b`) for a wide signal, 0 for a 1-bit one.
    prefix: u8,
    /// Wider than 32 bits: up to 8 groups of 8 digits instead of 4.
    wide: bool,
}

/// The text of a timestamp above its last 8 digits, `#` and those digits, kept from one
/// timestamp to the next: at a clock period of ~15 ns it changes once every 6,667 cycles.
struct TimePrefix {
    /// The time divided by 10^8.
    high: u64,
    /// `#` and the decimal digits of `high` (at most 12), zero padded.
    text: [u8; 16],
    len: usize,
}

impl TimePrefix {
    fn of(high: u64) -> TimePrefix {
        let digits = format!("#{high}");
        let mut text = [0u8; 16];
        text[..digits.len()].copy_from_slice(digits.as_bytes());
        TimePrefix {
            high,
            text,
            len: digits.len(),
        }
    }
}

/// The VCD writer: change detection in front of the VCD encoder.
pub type VcdWriter<W> = WaveWriter<VcdEncoder<W>>;

impl<W: Write> VcdWriter<W> {
    /// Start a dump whose time unit is 1 ps.
    pub fn new(out: W, version: &str) -> VcdWriter<W> {
        WaveWriter::with_encoder(VcdEncoder::new(out, version))
    }
}

/// The VCD text of declarations and changes.
pub struct VcdEncoder<W: Write> {
    out: W,
    /// Per signal, by id.
    signals: Vec<Signal>,
    /// The text above the last 8 digits of the last timestamp at or above 10^8.
    prefix: TimePrefix,
    error: Option<io::Error>,
    lines: Lines,
}

/// Lines gathered before they go to the destination in large writes: `buffer[..filled]`,
/// the rest scratch (`BUFFER_BYTES + SLACK_BYTES` long).
struct Lines {
    buffer: Vec<u8>,
    filled: usize,
}

impl Lines {
    /// The `LINE_SCRATCH` bytes from the fill mark on, as a fixed-size window (offsets
    /// bounded by construction leave no bounds checks in the formatting).
    #[inline(always)]
    fn window(&mut self) -> &mut [u8; LINE_SCRATCH] {
        (&mut self.buffer[self.filled..self.filled + LINE_SCRATCH])
            .try_into()
            .expect("a window of LINE_SCRATCH bytes")
    }
}

/// Decimal digits of `value` (at least 1): one more than a guess of log10 from the bit
/// length (log10(2) ~ 1233 / 4096, never too low), corrected by one comparison.
#[inline(always)]
fn decimal_digits(value: u64) -> usize {
    const POWERS: [u64; 20] = {
        let mut powers = [1u64; 20];
        let mut i = 1;
        while i < 20 {
            powers[i] = powers[i - 1] * 10;
            i += 1;
        }
        powers
    };
    let value = value | 1; // same digit count, and 0 has one digit
    let guess = (((64 - value.leading_zeros()) * 1233) >> 12) as usize;
    guess + 1 - (value < POWERS[guess]) as usize
}

/// `value` (< 10^8) as exactly 8 decimal digits.
#[inline(always)]
fn write_eight_digits(out: &mut [u8; 8], value: u64) {
    let (high, low) = ((value / 10_000) as usize, (value % 10_000) as usize);
    out[0..2].copy_from_slice(&DECIMAL_PAIRS[high / 100]);
    out[2..4].copy_from_slice(&DECIMAL_PAIRS[high % 100]);
    out[4..6].copy_from_slice(&DECIMAL_PAIRS[low / 100]);
    out[6..8].copy_from_slice(&DECIMAL_PAIRS[low % 100]);
}

fn identifier(mut n: usize) -> String {
    let mut code = String::new();
    loop {
        code.push((33 + (n % 94) as u8) as char);
        n /= 94;
        if n == 0 {
            return code;
        }
        n -= 1;
    }
}

impl<W: Write> VcdEncoder<W> {
    /// Start a dump whose time unit is 1 ps.
    pub fn new(out: W, version: &str) -> VcdEncoder<W> {
        let mut vcd = VcdEncoder {
            out,
            signals: Vec::new(),
            prefix: TimePrefix::of(0),
            error: None,
            lines: Lines {
                buffer: vec![0; BUFFER_BYTES + SLACK_BYTES],
                filled: 0,
            },
        };
        vcd.put(&format!("$version {version} $end\n$timescale 1ps $end\n"));
        vcd
    }

    /// Append header text of any length.
    fn put(&mut self, text: &str) {
        let bytes = text.as_bytes();
        if self.lines.filled + bytes.len() > BUFFER_BYTES {
            self.spill();
        }
        if bytes.len() > BUFFER_BYTES {
            self.write_out(bytes);
        } else {
            let Lines { buffer, filled } = &mut self.lines;
            buffer[*filled..*filled + bytes.len()].copy_from_slice(bytes);
            *filled += bytes.len();
        }
    }

    fn write_out(&mut self, bytes: &[u8]) {
        if self.error.is_none() {
            if let Err(e) = self.out.write_all(bytes) {
                self.error = Some(e);
            }
        }
    }

    #[inline(never)]
    fn spill(&mut self) {
        if self.error.is_none() {
            if let Err(e) = self.out.write_all(&self.lines.buffer[..self.lines.filled]) {
                self.error = Some(e);
            }
        }
        self.lines.filled = 0;
    }

    /// `#TIME\n`, before the first change at it.
    #[inline(never)]
    fn write_time(&mut self, time: u64) {
        let high = time / LOW_DIGITS_RANGE;
        if high == 0 {
            self.write_short_time(time);
        } else {
            if high != self.prefix.high {
                self.prefix = TimePrefix::of(high);
            }
            // The kept `#` and high digits, then 8 digits and the newline.
            let prefix = &self.prefix;
            let buffer = self.lines.window();
            buffer[..16].copy_from_slice(&prefix.text);
            let at = prefix.len & 15;
            let low: &mut [u8; 8] = (&mut buffer[at..at + 8]).try_into().expect("8 bytes");
            write_eight_digits(low, time % LOW_DIGITS_RANGE);
            buffer[at + 8] = b'\n';
            self.lines.filled += at + 9;
        }
    }

    /// `#TIME\n` for a time below 10^8 (the first 100 µs), digit pair by pair.
    #[cold]
    fn write_short_time(&mut self, t: u64) {
        let length = decimal_digits(t);
        let buffer = self.lines.window();
        buffer[0] = b'#';
        buffer[1 + length] = b'\n';
        let digits = &mut buffer[1..1 + length];
        let mut rest = t as u32;
        let mut end = length;
        while end >= 2 {
            digits[end - 2..end].copy_from_slice(&DECIMAL_PAIRS[(rest % 100) as usize]);
            rest /= 100;
            end -= 2;
        }
        if end == 1 {
            digits[0] = b'0' + rest as u8;
        }
        self.lines.filled += 2 + length;
    }
}

impl<W: Write> WaveEncoder for VcdEncoder<W> {
    type Output = W;

    fn scope(&mut self, name: &str) {
        self.put(&format!("$scope module {name} $end\n"));
    }

    fn upscope(&mut self) {
        self.put("$upscope $end\n");
    }

    fn var(&mut self, kind: VarKind, name: &str, width: u32) {
        let id = self.signals.len();
        let code = identifier(id);
        let kind = match kind {
            VarKind::Wire => "wire",
            VarKind::Reg => "reg",
        };
        self.put(&format!("$var {kind} {width} {code} {name} $end\n"));
        // A usize needs at most 10 base-94 characters: the tail fits 16 bytes.
        let tail_text = if width == 1 {
            format!("{code}\n")
        } else {
            format!(" {code}\n")
        };
        let mut tail = [0u8; 16];
        tail[..tail_text.len()].copy_from_slice(tail_text.as_bytes());
        self.signals.push(Signal {
            mask: mask(width),
            tail,
            tail_len: tail_text.len() as u8,
            prefix: (width > 1) as u8,
            wide: width > 32,
        });
    }

    fn end_definitions(&mut self) {
        self.put("$enddefinitions $end\n");
    }

    #[inline(always)]
    fn time(&mut self, time: u64) {
        self.write_time(time);
    }

    /// The slack past the spill mark holds a timestamp and a whole block of lines, so the
    /// buffer is checked once, after the block.
    #[inline(always)]
    fn value(&mut self, id: usize, value: u64) {
        let signal = &self.signals[id];
        let at = self.lines.filled;
        let window: &mut [u8; LINE_SCRATCH] = (&mut self.lines.buffer[at..at + LINE_SCRATCH])
            .try_into()
            .expect("a window of LINE_SCRATCH bytes");
        self.lines.filled += write_line(window, signal, value);
    }

    #[inline(always)]
    fn block_end(&mut self) {
        if self.lines.filled >= BUFFER_BYTES {
            self.spill();
        }
    }

    fn end_at(&mut self, time: u64) {
        self.put(&format!("#{time}\n"));
    }

    /// Flush and return the destination, or the first write error.
    fn finish(mut self) -> io::Result<W> {
        self.spill();
        if let Some(e) = self.error.take() {
            return Err(e);
        }
        self.out.flush()?;
        Ok(self.out)
    }
}

/// Write `signal`'s line for `value` (masked) at the start of `buffer`; returns the
/// line's length.
///
/// The formatter writes whole groups (a fixed-size window: with the offsets below bounded
/// by construction, no bounds checks are left): the most significant digit at bit 63, then
/// groups of 8 from the top (4 of them unless the signal is wider than 32 bits), so the bytes
/// past the last digit are overwritten by the tail or left as scratch.
#[inline(always)]
fn write_line(buffer: &mut [u8; LINE_SCRATCH], signal: &Signal, value: u64) -> usize {
    let value = value & signal.mask;
    // `b`, overwritten by the digits of a 1-bit signal (no prefix).
    buffer[0] = b'b';
    let digits = 64 - (value | 1).leading_zeros() as usize;
    let groups = (value << (64 - digits)).to_be_bytes();
    let at = (signal.prefix & 1) as usize;
    for (group, &byte) in groups[..4].iter().enumerate() {
        buffer[at + 8 * group..at + 8 * group + 8].copy_from_slice(&BINARY_DIGITS[byte as usize]);
    }
    if signal.wide {
        for (group, &byte) in groups.iter().enumerate().skip(4) {
            buffer[at + 8 * group..at + 8 * group + 8]
                .copy_from_slice(&BINARY_DIGITS[byte as usize]);
        }
    }
    let at = at + digits;
    buffer[at..at + 16].copy_from_slice(&signal.tail);
    at + (signal.tail_len & 15) as usize
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_header_and_only_changes() {
        let mut vcd = VcdWriter::new(Vec::new(), "test");
        vcd.scope("top");
        let a = vcd.var(VarKind::Wire, "a", 1);
        let b = vcd.var(VarKind::Reg, "b", 4);
        vcd.upscope();
        vcd.end_definitions();
        vcd.set_time(0);
        vcd.change(a, 1);
        vcd.change(b, 0x15); // masked to 4 bits
        vcd.set_time(15);
        vcd.change(a, 1);
        vcd.change(b, 5);
        vcd.set_time(30);
        vcd.change(a, 0);
        let text = String::from_utf8(vcd.finish().unwrap()).unwrap();
        assert_eq!(
            text,
            "$version test $end\n$timescale 1ps $end\n$scope module top $end\n\
             $var wire 1 ! a $end\n$var reg 4 \" b $end\n$upscope $end\n$enddefinitions $end\n\
             #0\n1!\nb101 \"\n#30\n0!\n"
        );
    }

    #[test]
    fn decimal_digit_counts() {
        for (value, digits) in [(0, 1), (9, 1), (10, 2), (99, 2), (100, 3), (999_999, 6)] {
            assert_eq!(decimal_digits(value), digits);
        }
        let mut power = 1u64;
        for digits in 1..20 {
            assert_eq!(decimal_digits(power), digits);
            assert_eq!(decimal_digits(power * 10 - 1), digits);
            power *= 10;
        }
        assert_eq!(decimal_digits(power), 20);
        assert_eq!(decimal_digits(u64::MAX), 20);
    }

    #[test]
    fn identifiers_are_distinct() {
        let codes: std::collections::HashSet<_> = (0..20000).map(identifier).collect();
        assert_eq!(codes.len(), 20000);
        assert_eq!(identifier(0), "!");
        assert_eq!(identifier(93), "~");
    }

    #[test]
    fn wide_values_and_long_timestamps_are_exact() {
        let mut vcd = VcdWriter::new(Vec::new(), "t");
        let wide = vcd.var(VarKind::Reg, "w", 64);
        let bit = vcd.var(VarKind::Wire, "b", 1);
        vcd.end_definitions();
        vcd.set_time(0);
        vcd.change(wide, u64::MAX); // first value: written although it is all ones
        vcd.set_time(9);
        vcd.change(wide, 1 << 63);
        vcd.set_time(10);
        vcd.change(wide, 0);
        vcd.change(bit, 0);
        vcd.set_time(99);
        vcd.change(wide, 0); // unchanged: no timestamp
        vcd.set_time(100);
        vcd.change(bit, 3); // masked to 1
        vcd.set_time(u64::MAX - 1);
        vcd.change(wide, 0b1011);
        vcd.end_at(u64::MAX);
        let text = String::from_utf8(vcd.finish().unwrap()).unwrap();
        let body = text.split_once("$enddefinitions $end\n").unwrap().1;
        let ones = "1".repeat(64);
        let top = format!("1{}", "0".repeat(63));
        assert_eq!(
            body,
            format!(
                "#0\nb{ones} !\n#9\nb{top} !\n#10\nb0 !\n0\"\n#100\n1\"\n\
                 #18446744073709551614\nb1011 !\n#18446744073709551615\n"
            )
        );
    }

    #[test]
    fn every_width_and_value_spills_intact() {
        // Far more than one buffer of lines; the expected text comes from `format!`.
        let mut vcd = VcdWriter::new(Vec::new(), "t");
        let ids: Vec<_> = (1..=64).map(|w| vcd.var(VarKind::Reg, "s", w)).collect();
        vcd.end_definitions();
        let header_end = "$enddefinitions $end\n";
        let mut expected = String::new();
        let mut state = 0x9E37_79B9_7F4A_7C15u64;
        let mut last = vec![None; 64];
        let mut time = 0;
        for step in 0..400u64 {
            // Timestamps of 1 to 15 digits, some just below powers of ten.
            time += step * step * step * 14_999 + (step % 3) * 99_999_999;
            vcd.set_time(time);
            let mut stamped = false;
            for (w, &id) in ids.iter().enumerate() {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                let value = (state >> (state % 64)) & mask(w as u32 + 1);
                vcd.change(id, value);
                if last[w] != Some(value) {
                    if !stamped {
                        expected += &format!("#{time}\n");
                        stamped = true;
                    }
                    let code = identifier(w);
                    expected += &if w == 0 {
                        format!("{value}{code}\n")
                    } else {
                        format!("b{value:b} {code}\n")
                    };
                    last[w] = Some(value);
                }
            }
        }
        let text = String::from_utf8(vcd.finish().unwrap()).unwrap();
        assert!(text.len() > 2 * BUFFER_BYTES);
        assert_eq!(text.split_once(header_end).unwrap().1, expected);
    }
}
