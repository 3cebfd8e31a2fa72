//! The argument groups and value parsers several commands share: how a
//! height source is read ([`HeightArgs`], flattened into `bake`, `trace`,
//! `compare` and `export-mesh`), the sizes, extents and addressing they
//! take, and the loading of the height map they name.

use anyhow::{bail, Context, Result};
use clap::Args;
use displace_core::convention::parse_size;
use displace_core::distance_map::Format;
use displace_core::io::height::{self, Channel, HeightOptions, HeightRange};
use displace_core::{Address, DistanceMap, Error, Extent, HeightMap};

/// How a height source is read (shared by `bake`, `trace`, `compare` and
/// `export-mesh`).
#[derive(Args, Debug, Clone)]
pub struct HeightArgs {
    /// Texels of a generated height map (`gen:...`), WxH [default: the
    /// distance map's W x H]
    #[arg(long, value_name = "WxH")]
    pub height_size: Option<String>,
    /// Channel of a colour image that holds the height [default: Rec. 709
    /// luminance]
    #[arg(long, value_parser = parse_channel)]
    pub channel: Option<Channel>,
    /// Texture addressing: a repeating height map bakes a tiling distance map
    #[arg(long, default_value = "clamp", value_parser = parse_address)]
    pub address: Address,
    /// Which values become heights 0 and 1: `auto` (the map's lowest and
    /// highest) or LO,HI in the file's values (an elevation model's metres,
    /// an image's codes) [default: 8/16-bit images by their full scale,
    /// float data as stored, in [0, 1]]
    #[arg(long, value_name = "auto|LO,HI", value_parser = parse_height_range, allow_hyphen_values = true)]
    pub height_range: Option<HeightRange>,
}

/// A displaced face given by its height map's reading and its extent, for
/// the commands that take either a face or a scene (`trace`,
/// `export-mesh`): with `--scene`, neither is needed. The height source
/// itself stays each command's own argument (a flag of `trace`, the
/// positional input of `export-mesh`).
#[derive(Args, Debug, Clone)]
pub struct FaceArgs {
    // How the height source is read.
    #[command(flatten)]
    pub height: HeightArgs,
    /// Physical width, height and displacement depth of the face
    #[arg(long, value_name = "SX,SY,SZ", value_parser = parse_extent, allow_hyphen_values = true,
          required_unless_present = "scene")]
    pub extent: Option<Extent>,
}

impl HeightArgs {
    /// The core's options for these arguments, `size` texels for a
    /// generated map.
    pub fn options(&self, size: [usize; 2]) -> HeightOptions {
        HeightOptions {
            channel: self.channel,
            size,
            address: self.address,
            range: self.height_range.unwrap_or_default(),
        }
    }
}

pub(crate) fn parse_height_range(s: &str) -> Result<HeightRange, String> {
    s.parse().map_err(|e: displace_core::Error| e.to_string())
}

pub fn parse_channel(s: &str) -> Result<Channel, String> {
    s.parse().map_err(|e: Error| e.to_string())
}

pub fn parse_address(s: &str) -> Result<Address, String> {
    s.parse().map_err(|e: Error| e.to_string())
}

pub fn parse_format(s: &str) -> Result<Format, String> {
    s.parse().map_err(|e: Error| e.to_string())
}

/// `SX,SY,SZ`: three positive finite numbers.
pub fn parse_extent(s: &str) -> Result<Extent, String> {
    let parts: Vec<&str> = s.split(',').collect();
    if parts.len() != 3 {
        return Err(format!("`{s}`: expected three numbers SX,SY,SZ"));
    }
    let mut v = [0.0f32; 3];
    for (o, p) in v.iter_mut().zip(&parts) {
        *o = p
            .trim()
            .parse()
            .map_err(|_| format!("`{s}`: `{p}` is not a number"))?;
    }
    Extent::new(v[0], v[1], v[2]).map_err(|e| e.to_string())
}

/// `WxHxD`, refused (before anything is allocated) when too large.
pub fn parse_map_size(s: &str) -> Result<[usize; 3]> {
    let size = parse_size::<3>(s).with_context(|| format!("--size {s}"))?;
    DistanceMap::check_size(size).with_context(|| format!("--size {s}"))?;
    Ok(size)
}

/// Loads `source`, with generated maps at `--height-size` or `default_size`.
pub fn load_height(source: &str, args: &HeightArgs, default_size: [usize; 2]) -> Result<HeightMap> {
    let opts = args.options(generated_size(source, args, default_size)?);
    height::load(source, &opts).with_context(|| format!("loading height map `{source}`"))
}

/// The size [`load_height`] would load, from the file's header alone (or
/// the generator's size): for checks made before anything is decoded.
pub fn height_dimensions(
    source: &str,
    args: &HeightArgs,
    default_size: [usize; 2],
) -> Result<[usize; 2]> {
    let opts = args.options(generated_size(source, args, default_size)?);
    height::dimensions(source, &opts).with_context(|| format!("loading height map `{source}`"))
}

/// The size of a generated map: `--height-size`, else `default_size`
/// (refused with a file, which has its own).
fn generated_size(source: &str, args: &HeightArgs, default_size: [usize; 2]) -> Result<[usize; 2]> {
    Ok(match &args.height_size {
        Some(s) if !source.starts_with(displace_core::generators::PREFIX) => bail!(
            "--height-size {s} sets the size of a generated height map (gen:...); `{source}` has its own size"
        ),
        Some(s) => {
            let size = parse_size::<2>(s).with_context(|| format!("--height-size {s}"))?;
            HeightMap::check_size(size[0], size[1])
                .with_context(|| format!("--height-size {s}"))?;
            size
        }
        None => default_size,
    })
}
