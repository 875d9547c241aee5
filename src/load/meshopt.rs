//! `EXT_meshopt_compression` (and its ratified form `KHR_meshopt_compression`): buffer views
//! stored encoded by meshoptimizer's vertex and index codecs, decoded here with meshoptimizer's
//! own decoder (the `meshopt` crate's bindings) into the bytes the view stands for.
//!
//! A compressed view names its encoded bytes in its extension (`buffer`, `byteOffset`,
//! `byteLength`), and what they decode to (`count` elements of `byteStride` bytes, `mode`
//! `ATTRIBUTES`, `TRIANGLES` or `INDICES`, and for attributes a `filter`). The view's own
//! `buffer` may be a fallback buffer that holds no data (`"fallback": true`). Every argument is
//! checked here against what the decoder asserts, so bad input is an error, never an abort.

use super::validate::Invalid;
use serde_json::Value;

/// The two names of the extension.
pub(crate) const NAMES: [&str; 2] = ["EXT_meshopt_compression", "KHR_meshopt_compression"];

/// The most bytes one view may decode to (1 GiB), as for any accessor without a view.
const MAX_DECODED: usize = 1 << 30;

/// A view's compression extension, if it has one: its name and its object.
pub(crate) fn extension(view: &Value) -> Option<(&'static str, &Value)> {
    NAMES.iter().find_map(|&n| {
        view["extensions"]
            .get(n)
            .filter(|e| e.is_object())
            .map(|e| (n, e))
    })
}

/// Whether buffer `b` is a fallback buffer: one whose bytes are only in compressed views.
pub(crate) fn is_fallback(buffer: &Value) -> bool {
    NAMES
        .iter()
        .any(|n| buffer["extensions"][n]["fallback"].as_bool() == Some(true))
}

/// Decodes every compressed view: entry `i` holds view `i`'s decoded bytes (cut to the view's
/// `byteLength`), `None` for a view stored plainly. `buffers` are the buffers' bytes; the views
/// may decode to `limit` bytes together (checked before anything is decoded, so a small file
/// cannot ask for unbounded memory).
pub(super) fn decode_views(
    json: &Value,
    buffers: &[Vec<u8>],
    limit: u64,
) -> Result<Vec<Option<Vec<u8>>>, Invalid> {
    let views = json["bufferViews"]
        .as_array()
        .map(Vec::as_slice)
        .unwrap_or(&[]);
    let mut total: u64 = 0;
    for (i, view) in views.iter().enumerate() {
        if let Some((name, ext)) = extension(view) {
            let size = |k: &str| ext[k].as_u64().unwrap_or(0);
            total = total.saturating_add(size("count").saturating_mul(size("byteStride")));
            if total > limit {
                return Err(Invalid {
                    item: format!("bufferViews[{i}].extensions.{name}"),
                    reason: format!(
                        "the compressed views decode to more than {} MiB together \
                         (--max-input-mib raises the limit)",
                        limit >> 20
                    ),
                });
            }
        }
    }
    views
        .iter()
        .enumerate()
        .map(|(i, view)| match extension(view) {
            None => Ok(None),
            Some((name, ext)) => {
                let item = format!("bufferViews[{i}].extensions.{name}");
                decode(ext, buffers)
                    .and_then(|bytes| {
                        let length = view["byteLength"].as_u64().unwrap_or(0) as usize;
                        if bytes.len() < length {
                            return Err(format!(
                                "decodes to {} bytes, fewer than the view's byteLength {length}",
                                bytes.len()
                            ));
                        }
                        Ok(Some(bytes[..length].to_vec()))
                    })
                    .map_err(|reason| Invalid { item, reason })
            }
        })
        .collect()
}

/// One view's decoded bytes.
fn decode(ext: &Value, buffers: &[Vec<u8>]) -> Result<Vec<u8>, String> {
    let field = |k: &str| ext[k].as_u64().map(|x| x as usize);
    let need = |k: &str| field(k).ok_or_else(|| format!("{k} is missing or not an integer"));
    let (buffer, offset, length) = (
        need("buffer")?,
        field("byteOffset").unwrap_or(0),
        need("byteLength")?,
    );
    let (stride, count) = (need("byteStride")?, need("count")?);
    let data = buffers
        .get(buffer)
        .ok_or_else(|| format!("buffer {buffer} does not exist"))?;
    let src = offset
        .checked_add(length)
        .and_then(|end| data.get(offset..end))
        .ok_or_else(|| {
            format!(
                "range {offset}..{} is outside buffer {buffer} ({} bytes)",
                offset.saturating_add(length),
                data.len()
            )
        })?;
    let size = count
        .checked_mul(stride)
        .filter(|&s| s <= MAX_DECODED)
        .ok_or_else(|| format!("{count} elements of {stride} bytes are more than 1 GiB"))?;
    let mut out = vec![0u8; size];
    let mode = ext["mode"].as_str().unwrap_or("");
    let filter = ext["filter"].as_str().unwrap_or("NONE");
    let code = match mode {
        "ATTRIBUTES" => {
            if stride == 0 || stride > 256 || !stride.is_multiple_of(4) {
                return Err(format!(
                    "byteStride {stride} of ATTRIBUTES must be a multiple of 4 from 4 to 256"
                ));
            }
            // SAFETY: `out` holds `count * stride` bytes and `src` is a live slice; the decoder
            // writes at most that many bytes and reads at most `src.len()` (it checks its input,
            // so a corrupt stream fails with a non-zero code, it does not read past it).
            unsafe {
                meshopt::ffi::meshopt_decodeVertexBuffer(
                    out.as_mut_ptr().cast(),
                    count,
                    stride,
                    src.as_ptr(),
                    src.len(),
                )
            }
        }
        "TRIANGLES" | "INDICES" => {
            if stride != 2 && stride != 4 {
                return Err(format!("byteStride {stride} of {mode} must be 2 or 4"));
            }
            if mode == "TRIANGLES" && !count.is_multiple_of(3) {
                return Err(format!("count {count} of TRIANGLES is not a multiple of 3"));
            }
            if filter != "NONE" {
                return Err(format!("filter {filter} does not apply to {mode}"));
            }
            let decode = if mode == "TRIANGLES" {
                meshopt::ffi::meshopt_decodeIndexBuffer
            } else {
                meshopt::ffi::meshopt_decodeIndexSequence
            };
            // SAFETY: as above, with `count` indices of `stride` bytes.
            unsafe {
                decode(
                    out.as_mut_ptr().cast(),
                    count,
                    stride,
                    src.as_ptr(),
                    src.len(),
                )
            }
        }
        other => {
            return Err(format!(
                "mode {other:?} is not ATTRIBUTES, TRIANGLES or INDICES"
            ));
        }
    };
    if code != 0 {
        return Err(format!(
            "the {mode} stream does not decode (meshoptimizer error {code})"
        ));
    }
    let filter_fn = match filter {
        "NONE" => None,
        "OCTAHEDRAL" if stride == 4 || stride == 8 => {
            Some(meshopt::ffi::meshopt_decodeFilterOct as Filter)
        }
        "QUATERNION" if stride == 8 => Some(meshopt::ffi::meshopt_decodeFilterQuat as Filter),
        "EXPONENTIAL" => Some(meshopt::ffi::meshopt_decodeFilterExp as Filter),
        "COLOR" if stride == 4 || stride == 8 => {
            Some(meshopt::ffi::meshopt_decodeFilterColor as Filter)
        }
        _ => {
            return Err(format!(
                "filter {filter:?} does not apply to a byteStride of {stride}"
            ));
        }
    };
    if let Some(f) = filter_fn {
        // SAFETY: `out` holds `count` elements of `stride` bytes, a stride the filter accepts
        // (checked above; ATTRIBUTES strides are multiples of 4).
        unsafe { f(out.as_mut_ptr().cast(), count, stride) };
    }
    Ok(out)
}

type Filter = unsafe extern "C" fn(*mut std::os::raw::c_void, usize, usize);

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn encoded_vertices(v: &[[f32; 3]]) -> Vec<u8> {
        let v: Vec<[f32; 4]> = v.iter().map(|p| [p[0], p[1], p[2], 0.0]).collect();
        meshopt::encode_vertex_buffer(&v).expect("encodes")
    }

    #[test]
    fn encoded_vertices_and_indices_decode_to_the_original_bytes() {
        let verts: Vec<[f32; 3]> = (0..50)
            .map(|i| [i as f32, (i * i) as f32 * 0.5, -1.0])
            .collect();
        let vbytes = encoded_vertices(&verts);
        let indices: Vec<u32> = (0..48).flat_map(|i| [i, i + 1, i + 2]).collect();
        let ibytes = meshopt::encode_index_buffer(&indices, 50).expect("encodes");
        let mut buffer = vbytes.clone();
        buffer.extend_from_slice(&ibytes);
        let json = json!({"bufferViews": [
            {"buffer": 1, "byteLength": 800, "byteStride": 16, "extensions": {"EXT_meshopt_compression":
                {"buffer": 0, "byteLength": vbytes.len(), "byteStride": 16, "count": 50, "mode": "ATTRIBUTES"}}},
            {"buffer": 1, "byteLength": 576, "extensions": {"KHR_meshopt_compression":
                {"buffer": 0, "byteOffset": vbytes.len(), "byteLength": ibytes.len(), "byteStride": 4,
                 "count": 144, "mode": "TRIANGLES"}}},
            {"buffer": 0, "byteLength": 4},
        ]});
        let views = decode_views(&json, &[buffer, Vec::new()], 1 << 20).expect("decodes");
        let v = views[0].as_ref().unwrap();
        for (i, p) in verts.iter().enumerate() {
            for c in 0..3 {
                let b = &v[i * 16 + c * 4..i * 16 + c * 4 + 4];
                assert_eq!(f32::from_le_bytes(b.try_into().unwrap()), p[c]);
            }
        }
        let idx: Vec<u32> = views[1]
            .as_ref()
            .unwrap()
            .chunks_exact(4)
            .map(|c| u32::from_le_bytes(c.try_into().unwrap()))
            .collect();
        // The codec keeps each triangle and its winding, not its first corner.
        let rotated = |t: &[u32]| {
            let k = (0..3).min_by_key(|&k| t[k]).unwrap();
            [t[k], t[(k + 1) % 3], t[(k + 2) % 3]]
        };
        let tris = |i: &[u32]| i.chunks_exact(3).map(rotated).collect::<Vec<_>>();
        assert_eq!(tris(&idx), tris(&indices));
        assert!(views[2].is_none());
    }

    #[test]
    fn a_corrupt_or_inconsistent_compressed_view_is_an_error_naming_it() {
        let vbytes = encoded_vertices(&[[1.0, 2.0, 3.0]; 10]);
        let view = |ext: Value| {
            json!({"bufferViews": [{"buffer": 0, "byteLength": 160,
            "extensions": {"EXT_meshopt_compression": ext}}]})
        };
        let cases = [
            (
                json!({"buffer": 0, "byteLength": vbytes.len(), "byteStride": 16, "count": 10, "mode": "ATTRIBUTES", "filter": "QUATERNION"}),
                "filter",
            ),
            (
                json!({"buffer": 0, "byteLength": vbytes.len(), "byteStride": 6, "count": 10, "mode": "ATTRIBUTES"}),
                "byteStride 6",
            ),
            (
                json!({"buffer": 0, "byteLength": vbytes.len() + 1, "byteStride": 16, "count": 10, "mode": "ATTRIBUTES"}),
                "outside buffer 0",
            ),
            (
                json!({"buffer": 0, "byteLength": 8, "byteStride": 16, "count": 10, "mode": "ATTRIBUTES"}),
                "does not decode",
            ),
            (
                json!({"buffer": 0, "byteLength": vbytes.len(), "byteStride": 16, "count": 1usize << 40, "mode": "ATTRIBUTES"}),
                "1 GiB",
            ),
            (
                json!({"buffer": 0, "byteLength": vbytes.len(), "byteStride": 4, "count": 10, "mode": "TRIANGLES"}),
                "multiple of 3",
            ),
            (
                json!({"buffer": 0, "byteLength": vbytes.len(), "byteStride": 16, "count": 10, "mode": "POINTS"}),
                "mode",
            ),
            (
                json!({"buffer": 0, "byteLength": vbytes.len(), "byteStride": 16, "count": 5, "mode": "ATTRIBUTES"}),
                "fewer than",
            ),
        ];
        // Together past the limit: refused before anything is decoded.
        let ext = json!({"buffer": 0, "byteLength": vbytes.len(), "byteStride": 16, "count": 10,
            "mode": "ATTRIBUTES"});
        let e = decode_views(&view(ext), std::slice::from_ref(&vbytes), 100).expect_err("limit");
        assert!(e.reason.contains("--max-input-mib"), "{}", e.reason);
        for (ext, want) in cases {
            let e = decode_views(&view(ext.clone()), std::slice::from_ref(&vbytes), u64::MAX)
                .expect_err(want);
            assert_eq!(e.item, "bufferViews[0].extensions.EXT_meshopt_compression");
            assert!(e.reason.contains(want), "{ext}: {}", e.reason);
        }
    }
}
