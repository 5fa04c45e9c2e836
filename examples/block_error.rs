//! Compares a test EXR with a reference EXR of the same size by the image
//! means and the mean relative error of the `B` x `B` block means (the
//! figures the README gives for photon mapping against the path tracer),
//! and the five blocks with the largest errors.
//!
//! `cargo run --release --example block_error -- TEST.exr REFERENCE.exr [B]`

use prism::image::film::Film;

fn channel_mean(f: &Film, xs: std::ops::Range<u32>, ys: std::ops::Range<u32>) -> f64 {
    let mut s = 0.0;
    let n = xs.len() * ys.len();
    for y in ys {
        for x in xs.clone() {
            let p = f.get(x, y);
            s += (p.x + p.y + p.z) as f64 / 3.0;
        }
    }
    s / n as f64
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        return Err("usage: block_error TEST.exr REFERENCE.exr [B]".into());
    }
    let test = prism::image::metrics::read_exr(args[1].as_ref())?;
    let reference = prism::image::metrics::read_exr(args[2].as_ref())?;
    if (test.width, test.height) != (reference.width, reference.height) {
        return Err("the images differ in size".into());
    }
    let b: u32 = args.get(3).map_or(Ok(8), |s| s.parse())?;
    if b == 0 {
        return Err("the block size must be at least 1".into());
    }
    let (w, h) = (test.width, test.height);
    let (mt, mr) = (
        channel_mean(&test, 0..w, 0..h),
        channel_mean(&reference, 0..w, 0..h),
    );
    let (mut sum, mut worst, mut n) = (0.0f64, 0.0f64, 0);
    let mut errors = Vec::new();
    for by in 0..h / b {
        for bx in 0..w / b {
            let (xs, ys) = (bx * b..(bx + 1) * b, by * b..(by + 1) * b);
            let r = channel_mean(&reference, xs.clone(), ys.clone());
            let t = channel_mean(&test, xs, ys);
            let e = (t - r).abs() / r.max(1e-3);
            sum += e;
            worst = worst.max(e);
            errors.push((e, bx, by));
            n += 1;
        }
    }
    println!(
        "image mean {mt:.5} vs reference {mr:.5} ({:+.2}%); {b}x{b} block means: mean relative error {:.2}%, largest {:.2}% over {n} blocks",
        100.0 * (mt / mr - 1.0),
        100.0 * sum / n as f64,
        100.0 * worst
    );
    errors.sort_by(|a, b| b.0.total_cmp(&a.0));
    let top: Vec<String> = errors
        .iter()
        .take(5)
        .map(|(e, x, y)| format!("({x},{y}) {:.1}%", 100.0 * e))
        .collect();
    println!("largest blocks (column, row): {}", top.join(", "));
    Ok(())
}
