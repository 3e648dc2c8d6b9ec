//! Fuzzes the streaming frame decoder: any byte stream, split anywhere, must never panic; the
//! decoder must hold at most its capacity; and any frame it accepts must re-encode to a frame
//! that decodes to the same message (no "valid" message out of garbage that is not canonical).
#![no_main]

use libfuzzer_sys::fuzz_target;
use skinbrdf_protocol::{encode_to_vec, DeviceMessage, FrameDecoder, Request};

fuzz_target!(|data: &[u8]| {
    // The first byte chooses the split size, so the fuzzer explores chunking too.
    let (split, rest) = match data.split_first() {
        Some((s, r)) => ((*s as usize % 64) + 1, r),
        None => return,
    };
    let mut dev = FrameDecoder::<256>::new();
    let mut host = FrameDecoder::<1024>::new();
    for chunk in rest.chunks(split) {
        let mut input = chunk;
        while let Some((r, more)) = dev.feed::<Request>(input) {
            if let Ok(req) = r {
                let again = encode_to_vec(&req).expect("a decoded request re-encodes");
                let mut d = FrameDecoder::<1024>::new();
                let (back, _) = d.feed::<Request>(&again).expect("one frame");
                assert_eq!(back.expect("round trip"), req);
            }
            input = more;
        }
        assert!(dev.pending_len() <= 256);
        let mut input = chunk;
        while let Some((r, more)) = host.feed::<DeviceMessage>(input) {
            if let Ok(msg) = r {
                let again = encode_to_vec(&msg).expect("a decoded message re-encodes");
                let mut d = FrameDecoder::<1024>::new();
                let (back, _) = d.feed::<DeviceMessage>(&again).expect("one frame");
                assert_eq!(back.expect("round trip"), msg);
            }
            input = more;
        }
    }
});
