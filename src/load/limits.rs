//! Resource limits of a bake, checked before the work they bound: a file that exceeds one is
//! refused with an error that names the item and the command-line option that raises the
//! limit. The defaults fit a machine with 24 GB of memory.

/// Resource limits of reading and baking one glTF file. Each field has a command-line option
/// of the same name (`--max-...`) that raises or lowers it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Limits {
    /// The most bytes the input file and each file it reads (buffers, images) may hold, and
    /// the input with its buffer files together (`--max-input-mib`, in MiB on the command
    /// line).
    pub input_bytes: u64,
    /// The largest width and the largest height of an image, pixels (`--max-image-size`).
    pub image_side: u32,
    /// The most memory one decoded image may take, bytes, counted as 12 bytes a pixel (the
    /// linear RGB floats its mean colour is taken from; `--max-image-mib`, in MiB). All the
    /// images a bake decodes may take [`IMAGES_TOGETHER`] times it together (one at a time:
    /// this bounds the time spent decoding).
    pub image_bytes: u64,
    /// The most nodes (`--max-nodes`).
    pub nodes: usize,
    /// The most mesh instances: primitives placed by the nodes of the scene, after the node
    /// graph is flattened (`--max-instances`).
    pub instances: usize,
    /// The most primitives over all meshes of the file (`--max-primitives`).
    pub primitives: usize,
    /// The most triangles over all instances, as their accessors count them before they are
    /// read (`--max-triangles`).
    pub triangles: usize,
    /// The most receiver polygons (coplanar, edge-connected triangles of one material), counted
    /// once the scene is built, before any stage that works per polygon: the atlas takes about
    /// 90 KiB a polygon (`--max-polygons`).
    pub polygons: usize,
}

/// One mebibyte, bytes.
pub const MIB: u64 = 1 << 20;

impl Default for Limits {
    fn default() -> Self {
        Limits {
            input_bytes: DEFAULT_INPUT_MIB * MIB,
            image_side: DEFAULT_IMAGE_SIDE,
            image_bytes: DEFAULT_IMAGE_MIB * MIB,
            nodes: DEFAULT_NODES,
            instances: DEFAULT_INSTANCES,
            primitives: DEFAULT_PRIMITIVES,
            triangles: DEFAULT_TRIANGLES,
            polygons: DEFAULT_POLYGONS,
        }
    }
}

/// Default of [`Limits::input_bytes`], MiB.
pub const DEFAULT_INPUT_MIB: u64 = 2048;
/// Default of [`Limits::image_side`], pixels.
pub const DEFAULT_IMAGE_SIDE: u32 = 16384;
/// Default of [`Limits::image_bytes`], MiB (a 16384 x 16384 image takes 3 GiB).
pub const DEFAULT_IMAGE_MIB: u64 = 3072;
/// Default of [`Limits::nodes`].
pub const DEFAULT_NODES: usize = 1_000_000;
/// Default of [`Limits::instances`].
pub const DEFAULT_INSTANCES: usize = 10_000;
/// Default of [`Limits::primitives`].
pub const DEFAULT_PRIMITIVES: usize = 20_000;
/// Default of [`Limits::triangles`].
pub const DEFAULT_TRIANGLES: usize = 1_000_000;
/// Default of [`Limits::polygons`]: about 18 GB of atlas.
pub const DEFAULT_POLYGONS: usize = 200_000;

/// Bytes a decoded pixel is counted as against [`Limits::image_bytes`]: three f32 channels.
const PIXEL_BYTES: u64 = 12;

/// How many times [`Limits::image_bytes`] all the images of a bake may take together.
pub(crate) const IMAGES_TOGETHER: u64 = 8;

/// Bytes a decoded `width` x `height` image is counted as against [`Limits::image_bytes`].
pub(crate) fn decoded_bytes(width: u32, height: u32) -> u64 {
    u64::from(width) * u64::from(height) * PIXEL_BYTES
}

/// Decodes an image within `limits`: the outer error says which limit it is past (checked on
/// the header before anything is decoded, then by the decoder's own allocation limits), the
/// inner one why it cannot be decoded at all.
pub(crate) fn decode_image(
    bytes: &[u8],
    limits: &Limits,
) -> Result<Result<image::DynamicImage, String>, String> {
    let reader = || {
        image::ImageReader::new(std::io::Cursor::new(bytes))
            .with_guessed_format()
            .map_err(|e| e.to_string())
    };
    let (width, height) =
        match reader().and_then(|r| r.into_dimensions().map_err(|e| e.to_string())) {
            Ok(size) => size,
            Err(e) => return Ok(Err(e)),
        };
    let side = limits.image_side;
    if width > side || height > side {
        return Err(format!(
            "is {width} x {height} pixels, more than {side} on a side (--max-image-size raises \
             the limit)"
        ));
    }
    let needed = decoded_bytes(width, height);
    if needed > limits.image_bytes {
        return Err(format!(
            "is {width} x {height} pixels, which takes {} MiB decoded, more than {} MiB \
             (--max-image-mib raises the limit)",
            needed.div_ceil(MIB),
            limits.image_bytes / MIB
        ));
    }
    let mut decoder_limits = image::Limits::default();
    decoder_limits.max_image_width = Some(side);
    decoder_limits.max_image_height = Some(side);
    decoder_limits.max_alloc = Some(limits.image_bytes);
    let mut reader = match reader() {
        Ok(r) => r,
        Err(e) => return Ok(Err(e)),
    };
    reader.limits(decoder_limits);
    match reader.decode() {
        Ok(img) => Ok(Ok(img)),
        Err(image::ImageError::Limits(e)) => Err(format!(
            "is {width} x {height} pixels and needs more memory to decode than {} MiB \
             (--max-image-mib raises the limit): {e}",
            limits.image_bytes / MIB
        )),
        Err(e) => Ok(Err(e.to_string())),
    }
}

/// Checks the counts of the JSON against `limits` before anything is read: the nodes and the
/// primitives of all meshes.
pub(crate) fn check_counts(
    json: &serde_json::Value,
    limits: &Limits,
) -> Result<(), super::validate::Invalid> {
    let len = |key: &str| {
        json.get(key)
            .and_then(serde_json::Value::as_array)
            .map_or(0, Vec::len)
    };
    let nodes = len("nodes");
    if nodes > limits.nodes {
        return Err(super::validate::Invalid {
            item: "nodes".into(),
            reason: format!(
                "{nodes} nodes, more than {} (--max-nodes raises the limit)",
                limits.nodes
            ),
        });
    }
    let primitives: usize = json
        .get("meshes")
        .and_then(serde_json::Value::as_array)
        .map_or(0, |meshes| {
            meshes
                .iter()
                .map(|m| {
                    m.get("primitives")
                        .and_then(serde_json::Value::as_array)
                        .map_or(0, Vec::len)
                })
                .sum()
        });
    if primitives > limits.primitives {
        return Err(super::validate::Invalid {
            item: "meshes".into(),
            reason: format!(
                "{primitives} primitives in all, more than {} (--max-primitives raises the limit)",
                limits.primitives
            ),
        });
    }
    Ok(())
}
