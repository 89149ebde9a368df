//! `cargo run -p alfd-bridge --example fuzz_seeds -- DIR`: writes a valid frame of every kind a
//! peer sends (`alfd_bridge::peer_bytes::valid_frames`) to DIR, one file each, as the fuzzer's
//! seed corpus.

fn main() -> std::io::Result<()> {
    let dir = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "corpus".to_owned());
    std::fs::create_dir_all(&dir)?;
    for (i, bytes) in alfd_bridge::peer_bytes::valid_frames().iter().enumerate() {
        std::fs::write(
            std::path::Path::new(&dir).join(format!("seed-{i:02}")),
            bytes,
        )?;
    }
    Ok(())
}
