//! Structured fuzzing on stable Rust: 10^7 inputs (`SKINBRDF_FUZZ_INPUTS` to change) built from
//! the golden frames of `docs/protocol.md` by bit flips, byte insertions and deletions,
//! truncations, splices of two frames, corrupted COBS length codes and CRCs, payload mutations
//! re-framed with a correct CRC (so postcard and the request handler see them), and random
//! bytes. Each input goes through the device's streaming decoder into a [`Sequencer`] (the
//! firmware's request handling) and through the host's decoder, followed by two valid frames.
//!
//! Checked for every input: no panic; the decoder never holds more than its buffer; the second
//! valid frame after any garbage decodes to its message (resynchronisation within one frame:
//! the first may be lost, glued to the garbage); every message the sequencer answers with
//! encodes into one frame; the sequencer's queue never exceeds its bound; no camera or flash
//! line is held outside a running session. Throughput is in `docs/sequencer.md`.

#![allow(clippy::unwrap_used)] // test helpers outside #[test] fns

use std::time::Instant;

use skinbrdf_protocol::*;
use skinbrdf_sequencer::{Config, Input, Sequencer, TX_QUEUE_LEN};

/// Frames from `docs/protocol.md` section 5 (pinned by `protocol/tests/golden.rs`), as hex.
const GOLDEN_REQUESTS: &[&str] = &[
    "07 01 07 1d b6 a6 c6 00",
    "01 01 06 01 84 e9 46 88 00",
    "08 ac 02 01 02 2f 12 6a 00",
    "06 02 02 01 01 6d 1e 1e 80 89 7a e0 a7 12 a0 8d 06 a0 c2 1e c0 96 b1 02 a0 9c 01 \
     01 02 01 e8 07 7f 9b dc ff 00",
];
const GOLDEN_DEVICE: &[&str] = &[
    "01 01 01 01 18 01 05 30 2e 31 2e 30 08 53 49 4d 2d 30 30 30 31 01 d2 09 31 db c3 7d 00",
    "01 01 02 01 07 01 02 ab 96 6b fe 00",
    "02 01 04 05 01 02 01 1c 80 e4 97 d0 12 01 a0 f1 9d d0 12 01 a0 e2 a2 d0 12 \
     01 d2 e2 a2 d0 12 01 e0 c6 5b 05 72 55 ff 15 00",
    "11 01 01 87 80 80 80 10 01 01 e0 c6 5b 85 4c ae d6 00",
];

fn hex(s: &str) -> Vec<u8> {
    s.split_whitespace()
        .map(|b| u8::from_str_radix(b, 16).unwrap())
        .collect()
}

/// SplitMix64: fast, good enough to drive mutations, reproducible from the seed.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
    fn byte(&mut self) -> u8 {
        self.next() as u8
    }
}

fn cobs_encode(data: &[u8]) -> Vec<u8> {
    let mut out = vec![0u8];
    let mut code_at = 0;
    let mut code = 1u8;
    for &b in data {
        if b == 0 {
            out[code_at] = code;
            code_at = out.len();
            out.push(0);
            code = 1;
        } else {
            out.push(b);
            code += 1;
            if code == 0xff {
                out[code_at] = code;
                code_at = out.len();
                out.push(0);
                code = 1;
            }
        }
    }
    out[code_at] = code;
    out
}

fn cobs_decode(data: &[u8]) -> Option<Vec<u8>> {
    let mut out = Vec::new();
    let mut i = 0;
    while i < data.len() {
        let code = data[i] as usize;
        if code == 0 || i + code > data.len() {
            return None;
        }
        out.extend_from_slice(&data[i + 1..i + code]);
        i += code;
        if code < 0xff && i < data.len() {
            out.push(0);
        }
    }
    Some(out)
}

/// `COBS(payload ‖ crc) ‖ 0x00` with the CRC given (the right one, or a corrupted one).
fn frame_with_crc(payload: &[u8], crc: u32) -> Vec<u8> {
    let mut body = payload.to_vec();
    body.extend_from_slice(&crc.to_le_bytes());
    let mut f = cobs_encode(&body);
    f.push(0);
    f
}

fn payload_of(frame: &[u8]) -> Vec<u8> {
    let body = cobs_decode(&frame[..frame.len() - 1]).unwrap();
    body[..body.len() - CRC_LEN].to_vec()
}

/// Seeds: the golden frames plus one frame of every request variant.
fn seeds() -> (Vec<Vec<u8>>, Vec<Vec<u8>>) {
    let mut requests: Vec<Vec<u8>> = GOLDEN_REQUESTS.iter().map(|h| hex(h)).collect();
    let bodies = [
        RequestBody::Run {
            first_group: 0,
            last_group: 0,
        },
        RequestBody::Abort,
        RequestBody::AckRecords { next_index: 3 },
        RequestBody::FetchRecords { from_index: 1 },
        RequestBody::SetWatchdog {
            timeout_us: 2_000_000,
        },
        RequestBody::GetStatus,
    ];
    for (seq, body) in bodies.into_iter().enumerate() {
        let req = Request {
            seq: 10 + seq as u32,
            body,
        };
        requests.push(encode_to_vec(&req).unwrap().to_vec());
    }
    let device = GOLDEN_DEVICE.iter().map(|h| hex(h)).collect();
    (requests, device)
}

/// One fuzzed input from the seed frames.
fn mutate(rng: &mut Rng, seeds: &[Vec<u8>]) -> Vec<u8> {
    let f = &seeds[rng.below(seeds.len())];
    let mut v = f.clone();
    match rng.below(10) {
        0 => {
            for _ in 0..1 + rng.below(8) {
                let i = rng.below(v.len());
                v[i] ^= 1 << rng.below(8);
            }
        }
        1 => {
            for _ in 0..1 + rng.below(16) {
                let i = rng.below(v.len() + 1);
                let b = if rng.below(8) == 0 { 0 } else { rng.byte() };
                v.insert(i, b);
            }
        }
        2 => {
            for _ in 0..1 + rng.below(8) {
                if v.is_empty() {
                    break;
                }
                let i = rng.below(v.len());
                v.remove(i);
            }
        }
        3 => v.truncate(rng.below(v.len())),
        4 => {
            let g = &seeds[rng.below(seeds.len())];
            let (a, b) = (rng.below(v.len()), rng.below(g.len()));
            v.truncate(a);
            v.extend_from_slice(&g[b..]);
        }
        5 => {
            // A COBS code byte (a length field) set to anything non-zero.
            let p = rng.below(v.len().saturating_sub(1));
            v[if rng.below(2) == 0 { 0 } else { p }] = rng.byte().max(1);
        }
        6 => {
            // The payload intact, its CRC wrong.
            let p = payload_of(f);
            let crc = CRC32.checksum(&p) ^ (1 + rng.next() as u32 % u32::MAX);
            v = frame_with_crc(&p, crc);
        }
        7 => {
            // The payload mutated (varint lengths, variant indices, string bytes, extra or
            // missing bytes) and framed with a correct CRC: reaches postcard and the handler.
            let mut p = payload_of(f);
            for _ in 0..1 + rng.below(4) {
                match rng.below(4) {
                    0 if !p.is_empty() => {
                        let i = rng.below(p.len());
                        p[i] = rng.byte();
                    }
                    1 => {
                        let i = rng.below(p.len() + 1);
                        p.insert(i, rng.byte());
                    }
                    2 if !p.is_empty() => {
                        p.remove(rng.below(p.len()));
                    }
                    _ => p.truncate(rng.below(p.len() + 1)),
                }
            }
            v = frame_with_crc(&p, CRC32.checksum(&p));
        }
        8 => {
            // Random bytes, with zeros from none to many.
            let long = rng.below(16) == 0;
            let n = rng.below(if long { 3000 } else { 200 });
            let zero_every = 1 + rng.below(300);
            v = (0..n)
                .map(|_| {
                    if rng.below(zero_every) == 0 {
                        0
                    } else {
                        rng.byte()
                    }
                })
                .collect();
        }
        _ => {
            // Garbage glued in front of a frame.
            let n = rng.below(40);
            let mut g: Vec<u8> = (0..n).map(|_| rng.byte().max(1)).collect();
            g.extend_from_slice(&v);
            v = g;
        }
    }
    v
}

struct Totals {
    inputs: u64,
    bytes: u64,
    decoded: u64,
    /// Requests decoded from the mutated bytes themselves (not the valid frames after them).
    from_garbage: u64,
    errors: u64,
    handled_ok: u64,
}

fn run_worker(seed: u64, inputs: u64) -> Totals {
    let (req_seeds, dev_seeds) = seeds();
    let req_msgs: Vec<Request> = req_seeds
        .iter()
        .map(|f| {
            let mut d = FrameDecoder::<MAX_FRAME_LEN>::new();
            d.feed::<Request>(f).unwrap().0.unwrap()
        })
        .collect();
    let dev_msgs: Vec<DeviceMessage> = dev_seeds
        .iter()
        .map(|f| {
            let mut d = FrameDecoder::<MAX_FRAME_LEN>::new();
            d.feed::<DeviceMessage>(f).unwrap().0.unwrap()
        })
        .collect();
    let mut all_seeds = req_seeds.clone();
    all_seeds.extend(dev_seeds.iter().cloned());

    let mut rng = Rng(seed);
    let mut t = Totals {
        inputs: 0,
        bytes: 0,
        decoded: 0,
        from_garbage: 0,
        errors: 0,
        handled_ok: 0,
    };
    let fresh = |now| -> Sequencer<8> {
        let mut s = Sequencer::new(Config::new("0.1.0", "FUZZ", DeviceKind::Simulator), now);
        s.handle(
            now,
            Input::Request(Request {
                seq: 0,
                body: RequestBody::Hello {
                    protocol_version: PROTOCOL_VERSION,
                },
            }),
        );
        s
    };
    let mut now = 0u64;
    let mut seq = fresh(now);
    let mut dev_dec = FrameDecoder::<MAX_FRAME_LEN>::new();
    let mut host_dec = FrameDecoder::<MAX_FRAME_LEN>::new();
    let mut out = [0u8; MAX_FRAME_LEN];
    for i in 0..inputs {
        if i % 4096 == 0 {
            seq = fresh(now);
        }
        let garbage = mutate(&mut rng, &all_seeds);
        t.inputs += 1;
        t.bytes += garbage.len() as u64;

        // Device side: garbage, then two valid requests; the second must come out intact.
        let (a, b) = (rng.below(req_seeds.len()), rng.below(req_seeds.len()));
        let mut last: Option<Result<Request, FrameError>> = None;
        for (k, chunk) in [&garbage[..], &req_seeds[a], &req_seeds[b]]
            .into_iter()
            .enumerate()
        {
            let mut input = chunk;
            while let Some((r, rest)) = dev_dec.feed::<Request>(input) {
                assert!(dev_dec.pending_len() <= MAX_FRAME_LEN);
                match &r {
                    Ok(req) => {
                        t.decoded += 1;
                        t.from_garbage += u64::from(k == 0);
                        seq.handle(now, Input::Request(req.clone()));
                    }
                    Err(e) => {
                        t.errors += 1;
                        seq.handle(now, Input::BadFrame(*e));
                    }
                }
                last = Some(r);
                input = rest;
            }
        }
        assert_eq!(
            last,
            Some(Ok(req_msgs[b].clone())),
            "no resync after {garbage:02x?}"
        );
        assert_eq!(dev_dec.pending_len(), 0);

        // The firmware's side of the handling: time passes, deadlines fire, every message
        // fits a frame, the queue stays bounded, nothing is held outside a run.
        now += rng.below(50_000) as u64;
        seq.tick(now);
        let mut sent = 0;
        while let Some(m) = seq.pop_message() {
            encode(&m, &mut out).expect("every message fits one frame");
            sent += 1;
            if matches!(m, DeviceMessage::Response(_)) {
                t.handled_ok += 1;
            }
            // The queue plus a resend of the whole ring (8 records here).
            assert!(sent <= TX_QUEUE_LEN + 8, "message queue unbounded");
        }
        if seq.state() != SessionState::Running {
            assert!(seq.outputs().camera_and_flash_released());
        }

        // Host side: the same garbage before two device frames.
        let (a, b) = (rng.below(dev_seeds.len()), rng.below(dev_seeds.len()));
        let mut last: Option<Result<DeviceMessage, FrameError>> = None;
        for chunk in [&garbage[..], &dev_seeds[a], &dev_seeds[b]] {
            let mut input = chunk;
            while let Some((r, rest)) = host_dec.feed::<DeviceMessage>(input) {
                last = Some(r);
                input = rest;
            }
        }
        assert_eq!(last, Some(Ok(dev_msgs[b].clone())));
    }
    t
}

#[test]
fn ten_million_fuzzed_inputs_through_the_decoders_and_the_request_handler() {
    let total: u64 = std::env::var("SKINBRDF_FUZZ_INPUTS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(if cfg!(debug_assertions) {
            // An unoptimised build is ~30x slower: a smoke run; CI runs release.
            200_000
        } else {
            10_000_000
        });
    let workers = std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .clamp(1, 4) as u64;
    let start = Instant::now();
    let results: Vec<Totals> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..workers)
            .map(|w| {
                let n = total / workers + u64::from(w < total % workers);
                s.spawn(move || run_worker(0x5EED_0000 + w, n))
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    });
    let secs = start.elapsed().as_secs_f64();
    let sum = |f: fn(&Totals) -> u64| results.iter().map(f).sum::<u64>();
    let inputs = sum(|t| t.inputs);
    assert_eq!(inputs, total);
    println!(
        "fuzz: {inputs} inputs ({} MB of mutated bytes) on {workers} threads in {secs:.1} s \
         ({:.0} inputs/s); {} requests decoded and handled ({} from the mutated bytes), {} frame \
         errors, {} responses",
        sum(|t| t.bytes) / 1_000_000,
        inputs as f64 / secs,
        sum(|t| t.decoded),
        sum(|t| t.from_garbage),
        sum(|t| t.errors),
        sum(|t| t.handled_ok),
    );
    // The payload mutations must reach the handler, not only the CRC check.
    assert!(
        sum(|t| t.from_garbage) > inputs / 200,
        "mutated requests rarely reach the handler"
    );
}
