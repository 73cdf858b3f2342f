//! Write a damaged copy of a drive (every fifth point cloud cut short, every fifth JPEG
//! garbled; `rigcal::sim::damage`), for the damaged-drive benchmark in BENCHMARKS.md:
//!
//!     cargo run --release --no-default-features --example damage_drive -- IN.mcap OUT.mcap

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [from, to] = args.as_slice() else {
        eprintln!("usage: damage_drive IN.mcap OUT.mcap");
        std::process::exit(2);
    };
    match rigcal::sim::damage::damaged_copy(from.as_ref(), to.as_ref()) {
        Ok(n) => println!("{n} messages damaged; wrote {to}"),
        Err(e) => {
            eprintln!("damage_drive: {e}");
            std::process::exit(1);
        }
    }
}
