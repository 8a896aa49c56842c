//! `cargo run -p uavnav-dataset --example convert -- SRC DST`: converts between an ASL folder and
//! an `.mcap` recording (by extension) and prints what was written and how long it took.

use std::path::PathBuf;
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<PathBuf> = std::env::args_os().skip(1).map(PathBuf::from).collect();
    let [src, dst] = args.as_slice() else {
        eprintln!("usage: convert SRC DST   (an ASL folder or a .mcap file each)");
        std::process::exit(2);
    };
    let start = Instant::now();
    let summary = uavnav_dataset::convert::convert(src, dst)?;
    println!("{summary:?} in {:.2} s", start.elapsed().as_secs_f64());
    Ok(())
}
