//! Shard files and their merge.
//!
//! A shard is part of a render: some rectangles of the image (its
//! *parts*), each rendered with the samples `A..B` of every pixel's `spp`.
//! It is one OpenEXR file (written with the `exr` crate) whose display
//! window is the whole image and which has one part per rectangle, each
//! with its data window where the rectangle lies in the image. Every part's
//! header carries the same [`Manifest`]: the scene's content hash, the
//! settings, seed and `spp`, the shard's own spec and sample range, and
//! the Prism version.
//!
//! Channels of a part: `R`, `G`, `B` (32-bit float) hold each pixel's mean
//! over the shard's samples, which for a shard of all `spp` samples is the
//! final pixel, bit for bit. A shard of fewer samples (a *sample shard*)
//! also stores each pixel's exact sum and count, which is what merging
//! adds up: `count` (32-bit unsigned) and, per colour channel `C`, the ten
//! 32-bit words of its 320-bit exact sum, least significant first, as
//! `sum.C.0` to `sum.C.9` (see [`ExactSum`]).
//!
//! [`merge`] checks that a set of shards belongs to one render and covers
//! every pixel's samples exactly once, then returns the image: exactly the
//! image the whole render gives.

use std::collections::HashMap;
use std::io::Cursor;
use std::ops::Range;
use std::path::{Path, PathBuf};

use exr::prelude::{
    AnyChannel, AnyChannels, AttributeValue, Encoding, FlatSamples, Image, ImageAttributes,
    IntegerBounds, Layer, LayerAttributes, ReadChannels, ReadLayers, SmallVec, Text, Vec2,
    WritableImage,
};

use crate::core::error::{Error, Result};
use crate::core::math::Color;
use crate::core::settings::{MAX_PIXELS, MAX_SPP, RenderSettings};
use crate::core::window::RenderWindow;
use crate::image::film::{ExactSum, Film, PixelAccumulator, PixelSum, SUM_WORDS};
use crate::image::output::write_atomic;

/// Header attribute names of the manifest.
mod key {
    pub const VERSION: &str = "prism.version";
    pub const SCENE: &str = "prism.sceneSha256";
    pub const SETTINGS: &str = "prism.settings";
    pub const SEED: &str = "prism.seed";
    pub const SPP: &str = "prism.spp";
    pub const SHARD: &str = "prism.shard";
    pub const SAMPLES: &str = "prism.samples";
}

/// What a shard belongs to and what it holds, stored in every part's
/// header.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Manifest {
    /// Version of the Prism that rendered it.
    pub version: String,
    /// SHA-256 (hex) of the scene's content.
    pub scene_hash: String,
    /// Every setting that determines the pixels, as one line of text
    /// (image size, depth, transport, integrator, ...); shards merge only
    /// if these agree exactly.
    pub settings: String,
    /// Seed of the sample keys.
    pub seed: u64,
    /// Samples per pixel of the whole render.
    pub spp: u32,
    /// How the shard was asked for (`3/8`, `pixels 0,64,0,32`, ...), for
    /// messages.
    pub shard: String,
    /// The samples of each pixel this shard rendered, within `0..spp`.
    pub samples: Range<u32>,
}

/// One rectangle of a shard.
#[derive(Clone, Debug, PartialEq)]
pub struct ShardPart {
    /// First image column.
    pub x0: u32,
    /// First image row.
    pub y0: u32,
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Each pixel's mean over the shard's samples, row-major.
    pub means: Vec<Color>,
    /// Each pixel's exact sum and count, row-major: present in sample
    /// shards (fewer than `spp` samples) only.
    pub sums: Option<Vec<PixelSum>>,
}

impl ShardPart {
    /// The columns covered.
    pub fn columns(&self) -> Range<u32> {
        self.x0..self.x0 + self.width
    }

    /// The rows covered.
    pub fn rows(&self) -> Range<u32> {
        self.y0..self.y0 + self.height
    }
}

/// A shard: its manifest, the image size and its parts.
#[derive(Clone, Debug, PartialEq)]
pub struct Shard {
    /// What it belongs to.
    pub manifest: Manifest,
    /// Width of the whole image.
    pub width: u32,
    /// Height of the whole image.
    pub height: u32,
    /// Its rectangles.
    pub parts: Vec<ShardPart>,
}

impl Shard {
    /// The shard of a windowed render, from `film` and `sums` as the frame
    /// gives them (the window's pixels, its rows in order): one part per
    /// range of rows, with sums when the shard has only some of the
    /// samples (`sums` must then be given).
    pub fn from_window(
        manifest: Manifest,
        settings: &RenderSettings,
        window: &RenderWindow,
        film: &Film,
        sums: Option<&PixelAccumulator>,
    ) -> Shard {
        let sample_shard = window.samples != (0..settings.spp);
        let width = window.columns.end - window.columns.start;
        let mut parts = Vec::new();
        let mut first_row = 0usize;
        for r in &window.rows {
            let h = (r.end - r.start) as usize;
            let span = first_row * width as usize..(first_row + h) * width as usize;
            parts.push(ShardPart {
                x0: window.columns.start,
                y0: r.start,
                width,
                height: h as u32,
                means: film.pixels[span.clone()].to_vec(),
                sums: if sample_shard {
                    sums.map(|s| s.pixels()[span].to_vec())
                } else {
                    None
                },
            });
            first_row += h;
        }
        Shard {
            manifest,
            width: settings.width,
            height: settings.height,
            parts,
        }
    }

    /// True when the shard holds only some of each pixel's samples.
    pub fn is_sample_shard(&self) -> bool {
        self.manifest.samples != (0..self.manifest.spp)
    }
}

const SUM_CHANNELS: [&str; 3] = ["R", "G", "B"];

fn text_attribute(attrs: &HashMap<Text, AttributeValue>, name: &str) -> Option<String> {
    match attrs.get(&Text::from(name)) {
        Some(AttributeValue::Text(t)) => Some(t.to_string()),
        _ => None,
    }
}

/// Writes `shard` to `path` as a multi-part OpenEXR file, atomically.
pub fn write_shard(path: &Path, shard: &Shard) -> Result<()> {
    let err = |message: String| Error::Output {
        path: path.to_path_buf(),
        message,
    };
    let m = &shard.manifest;
    let text = |s: &str| {
        Text::new_or_none(s)
            .map(AttributeValue::Text)
            .ok_or_else(|| err(format!("manifest text is not plain ASCII: {s}")))
    };
    let mut manifest = HashMap::new();
    manifest.insert(Text::from(key::VERSION), text(&m.version)?);
    manifest.insert(Text::from(key::SCENE), text(&m.scene_hash)?);
    manifest.insert(Text::from(key::SETTINGS), text(&m.settings)?);
    manifest.insert(Text::from(key::SEED), text(&m.seed.to_string())?);
    manifest.insert(Text::from(key::SPP), text(&m.spp.to_string())?);
    manifest.insert(Text::from(key::SHARD), text(&m.shard)?);
    manifest.insert(
        Text::from(key::SAMPLES),
        text(&format!("{}..{}", m.samples.start, m.samples.end))?,
    );
    let mut layers = Vec::new();
    for p in &shard.parts {
        let mut channels: SmallVec<[AnyChannel<FlatSamples>; 4]> = SmallVec::new();
        for (c, name) in SUM_CHANNELS.iter().enumerate() {
            let values = p.means.iter().map(|m| m.to_array()[c]).collect();
            channels.push(AnyChannel::new(*name, FlatSamples::F32(values)));
        }
        if let Some(sums) = &p.sums {
            channels.push(AnyChannel::new(
                "count",
                FlatSamples::U32(sums.iter().map(|s| s.count()).collect()),
            ));
            let exact: Vec<[ExactSum; 3]> = sums.iter().map(PixelSum::sums).collect();
            for (c, name) in SUM_CHANNELS.iter().enumerate() {
                for word in 0..2 * SUM_WORDS {
                    let values = exact
                        .iter()
                        .map(|s| (s[c].0[word / 2] >> (32 * (word % 2))) as u32)
                        .collect();
                    channels.push(AnyChannel::new(
                        format!("sum.{name}.{word}").as_str(),
                        FlatSamples::U32(values),
                    ));
                }
            }
        }
        let mut attributes = LayerAttributes::named(
            format!(
                "rows {}-{} columns {}-{}",
                p.y0,
                p.y0 + p.height,
                p.x0,
                p.x0 + p.width
            )
            .as_str(),
        );
        attributes.layer_position = Vec2(p.x0 as i32, p.y0 as i32);
        attributes.other = manifest.clone();
        layers.push(Layer::new(
            Vec2(p.width as usize, p.height as usize),
            attributes,
            Encoding::SMALL_LOSSLESS,
            AnyChannels::sort(channels),
        ));
    }
    let display = IntegerBounds::new(
        Vec2(0, 0),
        Vec2(shard.width as usize, shard.height as usize),
    );
    let image = Image::from_layers(ImageAttributes::new(display), layers);
    let mut bytes = Cursor::new(Vec::new());
    image
        .write()
        .to_buffered(&mut bytes)
        .map_err(|e| err(e.to_string()))?;
    write_atomic(path, &bytes.into_inner())
}

/// Reads a shard written by [`write_shard`]; any other file, a truncated
/// one or one without a complete manifest is an [`Error::Load`] naming
/// `path`.
pub fn read_shard(path: &Path) -> Result<Shard> {
    let bad = |message: String| Error::load(path, message);
    let bytes = std::fs::read(path).map_err(|e| bad(format!("cannot read shard: {e}")))?;
    // Check the headers' sizes before reading pixels, so that a hostile
    // header cannot make the reader allocate without bound.
    let meta = exr::meta::MetaData::read_from_buffered(Cursor::new(&bytes), false)
        .map_err(|e| bad(format!("not a readable OpenEXR file: {e}")))?;
    for h in &meta.headers {
        let size = h.layer_size;
        if size.area() as u64 > MAX_PIXELS || h.channels.list.len() > 40 {
            return Err(bad("not a Prism shard: a part is too large".into()));
        }
    }
    let image = exr::prelude::read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .all_layers()
        .all_attributes()
        .non_parallel()
        .from_buffered(Cursor::new(&bytes))
        .map_err(|e| bad(format!("not a readable OpenEXR file (truncated?): {e}")))?;
    let display = image.attributes.display_window;
    if display.position != Vec2(0, 0) || display.size.area() as u64 > MAX_PIXELS {
        return Err(bad(
            "not a Prism shard: its display window does not start at 0,0".into(),
        ));
    }
    let (width, height) = (display.size.0 as u32, display.size.1 as u32);
    let mut manifest: Option<Manifest> = None;
    let mut parts = Vec::new();
    for (i, layer) in image.layer_data.iter().enumerate() {
        let attrs = &layer.attributes.other;
        let get = |k: &str| {
            text_attribute(attrs, k).ok_or_else(|| {
                bad(format!(
                    "not a Prism shard: part {i} has no '{k}' attribute (is it a plain image rather than a shard?)"
                ))
            })
        };
        let samples = get(key::SAMPLES)?;
        let samples = samples
            .split_once("..")
            .and_then(|(a, b)| Some(a.parse().ok()?..b.parse().ok()?))
            .ok_or_else(|| bad(format!("invalid sample range '{samples}' in the manifest")))?;
        let m = Manifest {
            version: get(key::VERSION)?,
            scene_hash: get(key::SCENE)?,
            settings: get(key::SETTINGS)?,
            seed: get(key::SEED)?
                .parse()
                .map_err(|_| bad("invalid seed in the manifest".into()))?,
            spp: get(key::SPP)?
                .parse()
                .map_err(|_| bad("invalid spp in the manifest".into()))?,
            shard: get(key::SHARD)?,
            samples,
        };
        if m.spp == 0
            || m.spp > MAX_SPP
            || m.samples.start >= m.samples.end
            || m.samples.end > m.spp
        {
            return Err(bad(format!(
                "invalid sample range {}..{} of {} spp in the manifest",
                m.samples.start, m.samples.end, m.spp
            )));
        }
        match &manifest {
            None => manifest = Some(m),
            Some(first) if *first != m => {
                return Err(bad(format!("part {i}'s manifest differs from part 0's")));
            }
            Some(_) => {}
        }
        let pos = layer.attributes.layer_position;
        let size = layer.size;
        if pos.0 < 0
            || pos.1 < 0
            || pos.0 as usize + size.0 > width as usize
            || pos.1 as usize + size.1 > height as usize
            || size.area() == 0
        {
            return Err(bad(format!(
                "part {i}'s data window ({},{} size {}x{}) is not inside the {width}x{height} image",
                pos.0, pos.1, size.0, size.1
            )));
        }
        let n = size.area();
        let channel = |name: &str| {
            layer
                .channel_data
                .list
                .iter()
                .find(|c| c.name == *name)
                .map(|c| &c.sample_data)
                .filter(|d| d.len() == n)
        };
        let f32s = |name: &str| match channel(name) {
            Some(FlatSamples::F32(v)) => Ok(v),
            _ => Err(bad(format!(
                "not a Prism shard: part {i} has no 32-bit float channel {name}"
            ))),
        };
        let u32s = |name: &str| match channel(name) {
            Some(FlatSamples::U32(v)) => Ok(v),
            _ => Err(bad(format!(
                "not a complete sample shard: part {i} has no 32-bit unsigned channel {name}"
            ))),
        };
        let (r, g, b) = (f32s("R")?, f32s("G")?, f32s("B")?);
        let means: Vec<Color> = (0..n).map(|k| Color::new(r[k], g[k], b[k])).collect();
        if !means.iter().all(|c| c.is_finite()) {
            return Err(bad(format!("part {i} has a NaN or infinite pixel")));
        }
        let manifest = manifest.as_ref().expect("set above");
        let sums = if manifest.samples != (0..manifest.spp) {
            let count = u32s("count")?;
            let words: Vec<Vec<&Vec<u32>>> = SUM_CHANNELS
                .iter()
                .map(|c| {
                    (0..2 * SUM_WORDS)
                        .map(|w| u32s(&format!("sum.{c}.{w}")))
                        .collect::<Result<Vec<_>>>()
                })
                .collect::<Result<_>>()?;
            let most = manifest.samples.end - manifest.samples.start;
            let mut sums = Vec::with_capacity(n);
            for k in 0..n {
                if count[k] > most {
                    return Err(bad(format!(
                        "part {i} counts {} samples in a pixel of a {most}-sample shard",
                        count[k]
                    )));
                }
                let channel = |c: usize| {
                    ExactSum(std::array::from_fn(|w| {
                        words[c][2 * w][k] as u64 | (words[c][2 * w + 1][k] as u64) << 32
                    }))
                };
                sums.push(PixelSum::from_parts(
                    [channel(0), channel(1), channel(2)],
                    count[k],
                ));
            }
            Some(sums)
        } else {
            None
        };
        parts.push(ShardPart {
            x0: pos.0 as u32,
            y0: pos.1 as u32,
            width: size.0 as u32,
            height: size.1 as u32,
            means,
            sums,
        });
    }
    let manifest = manifest.ok_or_else(|| bad("not a Prism shard: it has no parts".into()))?;
    Ok(Shard {
        manifest,
        width,
        height,
        parts,
    })
}

/// A shard and the file it came from.
#[derive(Clone, Debug)]
pub struct ShardFile {
    /// Where it was read from, for messages.
    pub path: PathBuf,
    /// Its content.
    pub shard: Shard,
}

fn intersects(a: &Range<u32>, b: &Range<u32>) -> bool {
    a.start < b.end && b.start < a.end
}

fn describe(p: &ShardPart) -> String {
    format!(
        "columns {}..{}, rows {}..{}",
        p.x0,
        p.x0 + p.width,
        p.y0,
        p.y0 + p.height
    )
}

/// Checks that `shards` are of one render and cover every pixel's samples
/// exactly once, then puts them together into the whole image.
///
/// Refused, with a message naming the file: shards whose scene hash,
/// settings, seed, `spp`, image size or Prism version differ from the
/// first's; parts whose pixels and sample ranges overlap (the same file
/// twice, or the same shard rendered twice, is a duplicate); and a set
/// that leaves a pixel, or some of its samples, uncovered.
pub fn merge(shards: &[ShardFile]) -> Result<Film> {
    let Some(first) = shards.first() else {
        return Err(Error::Invalid("no shards to merge".into()));
    };
    let m0 = &first.shard.manifest;
    let name = |f: &ShardFile| f.path.display().to_string();
    for f in &shards[1..] {
        let m = &f.shard.manifest;
        let differs = |what: &str, a: &str, b: &str| {
            Err(Error::Invalid(format!(
                "{}: {what} differs from {}'s ({a} against {b}): shards of different renders cannot be merged",
                name(f),
                name(first)
            )))
        };
        if m.scene_hash != m0.scene_hash {
            return differs(
                "rendered from a different scene: its scene hash",
                &m.scene_hash,
                &m0.scene_hash,
            );
        }
        if (f.shard.width, f.shard.height) != (first.shard.width, first.shard.height) {
            return differs(
                "its image size",
                &format!("{}x{}", f.shard.width, f.shard.height),
                &format!("{}x{}", first.shard.width, first.shard.height),
            );
        }
        if m.settings != m0.settings {
            return differs("its settings", &m.settings, &m0.settings);
        }
        if m.seed != m0.seed {
            return differs("its seed", &m.seed.to_string(), &m0.seed.to_string());
        }
        if m.spp != m0.spp {
            return differs("its spp", &m.spp.to_string(), &m0.spp.to_string());
        }
        if m.version != m0.version {
            return differs("its Prism version", &m.version, &m0.version);
        }
    }
    let (width, height, spp) = (first.shard.width, first.shard.height, m0.spp);

    // Overlaps: two parts sharing pixels and samples.
    let parts: Vec<(&ShardFile, &ShardPart)> = shards
        .iter()
        .flat_map(|f| f.shard.parts.iter().map(move |p| (f, p)))
        .collect();
    for (i, (fa, a)) in parts.iter().enumerate() {
        for (fb, b) in &parts[i + 1..] {
            let (sa, sb) = (&fa.shard.manifest.samples, &fb.shard.manifest.samples);
            if intersects(&a.columns(), &b.columns())
                && intersects(&a.rows(), &b.rows())
                && intersects(sa, sb)
            {
                let what = if a.columns() == b.columns() && a.rows() == b.rows() && sa == sb {
                    "duplicate"
                } else {
                    "overlap"
                };
                return Err(Error::Invalid(format!(
                    "{what}: {} ({}, samples {}..{}) and {} ({}, samples {}..{}) both render the same pixel samples",
                    name(fa),
                    describe(a),
                    sa.start,
                    sa.end,
                    name(fb),
                    describe(b),
                    sb.start,
                    sb.end
                )));
            }
        }
    }

    // Coverage: without overlaps, a pixel is complete when its parts'
    // sample ranges add up to spp.
    let mut covered = vec![0u32; width as usize * height as usize];
    for (f, p) in &parts {
        let n = f.shard.manifest.samples.end - f.shard.manifest.samples.start;
        for y in p.rows() {
            let row = y as usize * width as usize;
            for c in &mut covered[row + p.x0 as usize..row + (p.x0 + p.width) as usize] {
                *c += n;
            }
        }
    }
    if let Some(i) = covered.iter().position(|&c| c != spp) {
        let (x, y) = (i as u32 % width, i as u32 / width);
        let mut have: Vec<(Range<u32>, String)> = parts
            .iter()
            .filter(|(_, p)| p.columns().contains(&x) && p.rows().contains(&y))
            .map(|(f, _)| (f.shard.manifest.samples.clone(), name(f)))
            .collect();
        if have.is_empty() {
            let mut given: Vec<String> = shards
                .iter()
                .take(8)
                .map(|f| format!("{} ({})", name(f), f.shard.manifest.shard))
                .collect();
            if shards.len() > 8 {
                given.push(format!("and {} more", shards.len() - 8));
            }
            return Err(Error::Invalid(format!(
                "gap: pixel ({x}, {y}) is in none of the {} shard(s) given, a shard is missing (given: {})",
                shards.len(),
                given.join(", ")
            )));
        }
        have.sort_by_key(|(r, _)| r.start);
        let mut missing = Vec::new();
        let mut next = 0;
        for (r, _) in &have {
            if r.start > next {
                missing.push(format!("{next}..{}", r.start));
            }
            next = r.end;
        }
        if next < spp {
            missing.push(format!("{next}..{spp}"));
        }
        let present: Vec<String> = have
            .iter()
            .map(|(r, n)| format!("{n} ({}..{})", r.start, r.end))
            .collect();
        return Err(Error::Invalid(format!(
            "missing samples: pixel ({x}, {y}) has samples {} of {spp} in no shard (it has {}); a sample shard is missing",
            missing.join(", "),
            present.join(", ")
        )));
    }

    // Assemble: whole-sample parts give their pixels; sample shards' sums
    // add up, exactly, and are averaged once complete.
    let mut film = Film::new(width, height);
    let mut sums: Vec<PixelSum> = Vec::new();
    for (f, p) in &parts {
        for (k, (y, x)) in p
            .rows()
            .flat_map(|y| p.columns().map(move |x| (y, x)))
            .enumerate()
        {
            let i = y as usize * width as usize + x as usize;
            match &p.sums {
                None => film.pixels[i] = p.means[k],
                Some(s) => {
                    if sums.is_empty() {
                        sums = vec![PixelSum::default(); film.pixels.len()];
                    }
                    sums[i] = sums[i].merge(&s[k]).ok_or_else(|| {
                        Error::load(&f.path, "its pixel sums overflow: the file is corrupt")
                    })?;
                }
            }
        }
    }
    for (_, p) in &parts {
        if p.sums.is_some() {
            for y in p.rows() {
                for x in p.columns() {
                    let i = y as usize * width as usize + x as usize;
                    film.pixels[i] = sums[i].mean();
                }
            }
        }
    }
    Ok(film)
}
