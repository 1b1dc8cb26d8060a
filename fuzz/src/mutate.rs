//! Byte-level mutations of an input, as blind fuzzers make them: flip a bit, put an interesting
//! value (0, 0xff, a MAVLink magic, a sign bit, a float's NaN or infinity) somewhere, insert,
//! delete or repeat a run, splice in part of another input, cut the end. All draws come from
//! the caller's seeded generator, so a run is repeatable.

use rand::Rng;

/// Bytes that sit on the edges of what parsers check.
const INTERESTING_BYTES: &[u8] = &[
    0x00, 0x01, 0x7f, 0x80, 0xff, 0xfd, 0xfe, b'\n', b'\t', b' ', b',', b'#', b'=', b'"', b':',
    b'?', b'&', b'.', b'-', b'e',
];
/// Little-endian words and floats that break arithmetic: NaN, infinities, extremes.
const INTERESTING_WORDS: &[[u8; 4]] = &[
    [0x00, 0x00, 0xc0, 0x7f], // NaN
    [0x00, 0x00, 0x80, 0x7f], // +inf
    [0x00, 0x00, 0x80, 0xff], // -inf
    [0xff, 0xff, 0x7f, 0x7f], // f32::MAX
    [0xff, 0xff, 0xff, 0xff],
    [0x00, 0x00, 0x00, 0x80],
    [0x01, 0x00, 0x00, 0x00],
];
/// Text fragments for the text formats (URLs, TOML, parameter and mission files).
const INTERESTING_TEXT: &[&str] = &[
    "nan",
    "inf",
    "-inf",
    "1e39",
    "-0",
    "0x",
    "65536",
    "-1",
    "18446744073709551616",
    "tcpin:",
    "udpin:",
    "udpout:",
    "tcp:",
    "serial:",
    "replay:",
    "?speed=",
    "?trust=",
    "&rate=",
    "[::1]",
    "127.0.0.1:",
    "\t",
    "\r\n",
    "\"\"\"",
    "[[",
    "= [",
    "QGC WPL 110\n",
    "key = \"",
    "\u{feff}",
];

/// Applies one to four mutations to `input`; `other` is a second input to splice from.
pub fn mutate(input: &[u8], other: &[u8], rng: &mut impl Rng, max_len: usize) -> Vec<u8> {
    let mut out = input.to_vec();
    for _ in 0..rng.random_range(1..=4) {
        mutate_once(&mut out, other, rng);
    }
    out.truncate(max_len);
    out
}

fn mutate_once(out: &mut Vec<u8>, other: &[u8], rng: &mut impl Rng) {
    let len = out.len();
    match rng.random_range(0..10) {
        0 if len > 0 => {
            let i = rng.random_range(0..len);
            out[i] ^= 1 << rng.random_range(0..8);
        }
        1 if len > 0 => {
            let i = rng.random_range(0..len);
            out[i] = INTERESTING_BYTES[rng.random_range(0..INTERESTING_BYTES.len())];
        }
        2 if len > 0 => {
            let i = rng.random_range(0..len);
            out[i] = rng.random();
        }
        3 if len >= 4 => {
            let i = rng.random_range(0..=len - 4);
            let w = INTERESTING_WORDS[rng.random_range(0..INTERESTING_WORDS.len())];
            out[i..i + 4].copy_from_slice(&w);
        }
        4 => {
            let at = rng.random_range(0..=len);
            let t = INTERESTING_TEXT[rng.random_range(0..INTERESTING_TEXT.len())];
            out.splice(at..at, t.bytes());
        }
        5 if len > 0 => {
            let a = rng.random_range(0..len);
            let b = rng.random_range(a..=len.min(a + 64));
            out.drain(a..b);
        }
        6 if len > 0 => {
            // Repeat a run: frames and lines one after the other.
            let a = rng.random_range(0..len);
            let b = rng.random_range(a..=len.min(a + 300));
            let run = out[a..b].to_vec();
            let at = rng.random_range(0..=out.len());
            out.splice(at..at, run);
        }
        7 if !other.is_empty() => {
            let a = rng.random_range(0..other.len());
            let b = rng.random_range(a..=other.len());
            let at = rng.random_range(0..=len);
            out.splice(at..at, other[a..b].iter().copied());
        }
        8 if len > 0 => {
            let keep = rng.random_range(0..len);
            out.truncate(keep);
        }
        _ => {
            let at = rng.random_range(0..=len);
            let n = rng.random_range(1..=8);
            let bytes: Vec<u8> = (0..n).map(|_| rng.random()).collect();
            out.splice(at..at, bytes);
        }
    }
}
