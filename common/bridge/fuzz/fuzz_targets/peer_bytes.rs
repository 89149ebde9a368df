//! libFuzzer's target: any bytes, as a remote peer could send them, through everything a bridge
//! does with them before they touch the run. A panic is a finding.
#![no_main]

libfuzzer_sys::fuzz_target!(|bytes: &[u8]| {
    alfd_bridge::peer_bytes::take_in(bytes);
});
