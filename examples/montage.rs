//! Puts linear EXR images of the same height side by side (with a small
//! black gap) and writes the row as one PNG with Prism's default display
//! transform, for the README's comparison pictures:
//!
//! `cargo run --release --example montage -- OUT.png A.exr B.exr ...`

use prism::image::film::Film;
use prism::image::metrics::read_exr;
use prism::image::output::{PngOptions, write_image};

/// Pixels of black between two images.
const GAP: u32 = 4;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        return Err("usage: montage OUT.png A.exr [B.exr ...]".into());
    }
    let images = args[2..]
        .iter()
        .map(|p| read_exr(p.as_ref()))
        .collect::<Result<Vec<Film>, _>>()?;
    let height = images[0].height;
    if images.iter().any(|f| f.height != height) {
        return Err("the images differ in height".into());
    }
    let width = images.iter().map(|f| f.width).sum::<u32>() + GAP * (images.len() as u32 - 1);
    let mut out = Film::new(width, height);
    let mut x0 = 0;
    for f in &images {
        for y in 0..height {
            for x in 0..f.width {
                out.pixels[(y * width + x0 + x) as usize] = f.get(x, y);
            }
        }
        x0 += f.width + GAP;
    }
    write_image(args[1].as_ref(), &out, &PngOptions::default())?;
    Ok(())
}
