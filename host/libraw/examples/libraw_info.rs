//! Prints what LibRaw reads from raw files: `cargo run -p skinbrdf-libraw --example libraw_info -- FILE...`.

fn main() {
    println!("LibRaw {}", skinbrdf_libraw::version());
    for arg in std::env::args().skip(1) {
        let path = std::path::Path::new(&arg);
        match skinbrdf_libraw::RawFile::open(path) {
            Err(e) => println!("{arg}: {e}"),
            Ok(f) => {
                println!("{arg}:\n  {:?}\n  {:?}", f.header(), f.metadata());
                match f.photosites() {
                    Ok(p) => println!(
                        "  unpacked {} values, levels {:?} {}",
                        p.values.len(),
                        p.header.black_levels,
                        p.header.white_level
                    ),
                    Err(e) => println!("  {e}"),
                }
            }
        }
    }
}
