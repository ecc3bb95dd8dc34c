//! Metadata in PNG files: ancillary chunks (image data chunks are skipped, not read).

use std::io::{Read, Seek, SeekFrom, Write};

use super::{exif_for_output, Metadata, Text};

const XMP_KEYWORD: &str = "XML:com.adobe.xmp";
/// Chunks carried as stored.
const RAW_CHUNKS: [&[u8; 4]; 5] = [b"gAMA", b"cHRM", b"sRGB", b"cICP", b"pHYs"];
/// Largest metadata chunk read, and the most metadata kept from one file, decompressed texts and profiles
/// included (a PNG of many small zTXt chunks would otherwise inflate to a thousand times its size).
const MAX_CHUNK: u32 = 64 << 20;
/// Text longer than this is written compressed.
const COMPRESS_ABOVE: usize = 1024;

/// Decompress `data`, at most `room` bytes of it.
fn inflate(data: &[u8], room: usize) -> Result<Vec<u8>, String> {
    let mut out = Vec::new();
    flate2::read::ZlibDecoder::new(data)
        .take(room as u64 + 1)
        .read_to_end(&mut out)
        .map_err(|e| format!("cannot decompress: {e}"))?;
    if out.len() > room {
        return Err(format!(
            "decompresses to more than the {room} bytes left of the {MAX_CHUNK} kept from a file's metadata"
        ));
    }
    Ok(out)
}

fn deflate(data: &[u8]) -> Vec<u8> {
    let mut e = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
    e.write_all(data).expect("writing to memory");
    e.finish().expect("writing to memory")
}

/// Split `data` at its first NUL: (before, after).
fn split_nul(data: &[u8]) -> Option<(&[u8], &[u8])> {
    let i = data.iter().position(|&b| b == 0)?;
    Some((&data[..i], &data[i + 1..]))
}

fn latin1(bytes: &[u8]) -> String {
    bytes.iter().map(|&b| b as char).collect()
}

/// Decode a text chunk into (keyword, text bytes as stored in the text's encoding, is UTF-8), decompressing at
/// most `room` bytes.
fn text_chunk(kind: &[u8; 4], data: &[u8], room: usize) -> Result<(String, Vec<u8>, bool), String> {
    let (keyword, rest) = split_nul(data).ok_or("no keyword terminator")?;
    let keyword = latin1(keyword);
    match kind {
        b"tEXt" => Ok((keyword, rest.to_vec(), false)),
        b"zTXt" => {
            let (&method, z) = rest.split_first().ok_or("cut off")?;
            if method != 0 {
                return Err(format!("unknown compression method {method}"));
            }
            Ok((keyword, inflate(z, room)?, false))
        }
        _ => {
            // iTXt: compression flag, method, language tag\0, translated keyword\0, text.
            let [flag, method, ..] = *rest else {
                return Err("cut off".into());
            };
            let (_lang, rest) = split_nul(&rest[2..]).ok_or("no language terminator")?;
            let (_translated, text) = split_nul(rest).ok_or("no translated-keyword terminator")?;
            let text = match (flag, method) {
                (0, _) => text.to_vec(),
                (1, 0) => inflate(text, room)?,
                _ => return Err(format!("unknown compression method {method}")),
            };
            Ok((keyword, text, true))
        }
    }
}

/// ImageMagick's `Raw profile type NAME` text: `\nNAME\n   LENGTH\nHEX...`.
fn raw_profile(text: &str) -> Option<Vec<u8>> {
    let mut parts = text.split_whitespace();
    let _name = parts.next()?;
    let len: usize = parts.next()?.parse().ok()?;
    let hex: Vec<u8> = parts.flat_map(|p| p.bytes()).collect();
    if hex.len() != 2 * len {
        return None;
    }
    hex.chunks_exact(2)
        .map(|h| u8::from_str_radix(std::str::from_utf8(h).ok()?, 16).ok())
        .collect()
}

/// Read the ancillary chunks of a PNG stream.
pub(super) fn read(mut r: impl Read + Seek, meta: &mut Metadata) {
    let mut sig = [0u8; 8];
    if r.read_exact(&mut sig).is_err() || &sig != b"\x89PNG\r\n\x1a\n" {
        meta.problems.push("PNG: no signature".into());
        return;
    }
    let mut raw_profiles: Vec<(String, String)> = Vec::new();
    // Bytes of metadata kept so far (decompressed): at most MAX_CHUNK.
    let mut held = 0usize;
    loop {
        let mut head = [0u8; 8];
        if r.read_exact(&mut head).is_err() {
            meta.problems
                .push("PNG: file ends without an IEND chunk".into());
            break;
        }
        let len = u32::from_be_bytes([head[0], head[1], head[2], head[3]]);
        let kind: [u8; 4] = [head[4], head[5], head[6], head[7]];
        let wanted = matches!(&kind, b"iCCP" | b"eXIf" | b"tEXt" | b"zTXt" | b"iTXt")
            || RAW_CHUNKS.contains(&&kind);
        if &kind == b"IEND" {
            break;
        }
        if !wanted || len > MAX_CHUNK {
            if wanted {
                meta.problems.push(format!(
                    "PNG: {} chunk of {len} bytes is too large; left out",
                    latin1(&kind)
                ));
            }
            if r.seek(SeekFrom::Current(len as i64 + 4)).is_err() {
                break;
            }
            continue;
        }
        let mut data = vec![0u8; len as usize + 4];
        if r.read_exact(&mut data).is_err() {
            meta.problems
                .push(format!("PNG: {} chunk is cut off", latin1(&kind)));
            break;
        }
        let crc = u32::from_be_bytes([
            data[len as usize],
            data[len as usize + 1],
            data[len as usize + 2],
            data[len as usize + 3],
        ]);
        data.truncate(len as usize);
        let mut h = crc32fast::Hasher::new();
        h.update(&kind);
        h.update(&data);
        let name = latin1(&kind);
        if h.finalize() != crc {
            meta.problems
                .push(format!("PNG: {name} chunk fails its CRC check; left out"));
            continue;
        }
        let room = (MAX_CHUNK as usize).saturating_sub(held);
        if data.len() > room {
            meta.problems.push(format!(
                "PNG: {name} chunk left out: the file's metadata is beyond the {MAX_CHUNK} bytes kept"
            ));
            continue;
        }
        held += take_chunk(kind, data, room, meta, &mut raw_profiles);
    }
    use_raw_profiles(raw_profiles, meta);
}

/// Store one wanted, CRC-checked chunk in `meta`, decompressing at most `room` bytes; ImageMagick raw-profile
/// texts are also noted in `raw_profiles` as (profile kind in lower case, text). Returns the bytes kept.
fn take_chunk(
    kind: [u8; 4],
    data: Vec<u8>,
    room: usize,
    meta: &mut Metadata,
    raw_profiles: &mut Vec<(String, String)>,
) -> usize {
    let name = latin1(&kind);
    let mut kept = data.len();
    match &kind {
        b"iCCP" => {
            let profile = split_nul(&data)
                .and_then(|(_, rest)| rest.split_first())
                .ok_or_else(|| "cut off".to_string())
                .and_then(|(&method, z)| match method {
                    0 => inflate(z, room),
                    m => Err(format!("unknown compression method {m}")),
                });
            match profile {
                Ok(p) => {
                    kept = p.len();
                    meta.icc = Some(p)
                }
                Err(e) => meta
                    .problems
                    .push(format!("PNG: iCCP chunk {e}; ICC profile left out")),
            }
        }
        b"eXIf" => {
            let exif = data.strip_prefix(b"Exif\0\0").unwrap_or(&data);
            meta.exif = Some(exif.to_vec());
        }
        b"tEXt" | b"zTXt" | b"iTXt" => match text_chunk(&kind, &data, room) {
            Ok((keyword, text, _)) if keyword == XMP_KEYWORD => {
                kept = text.len();
                meta.xmp = Some(text)
            }
            Ok((keyword, text, utf8)) => {
                kept = text.len();
                let text = if utf8 {
                    String::from_utf8_lossy(&text).into_owned()
                } else {
                    latin1(&text)
                };
                if let Some(kind) = keyword.strip_prefix("Raw profile type ") {
                    raw_profiles.push((kind.to_ascii_lowercase(), text.clone()));
                }
                meta.text.push(Text { keyword, text });
            }
            Err(e) => meta
                .problems
                .push(format!("PNG: {name} chunk: {e}; left out")),
        },
        _ => meta.png_chunks.push((kind, data)),
    }
    kept
}

/// ImageMagick stores profiles as hex text. Use them where the proper chunk is missing; drop the text copies of
/// profiles that are carried properly, so the output does not hold them twice.
fn use_raw_profiles(raw_profiles: Vec<(String, String)>, meta: &mut Metadata) {
    for (kind, text) in raw_profiles {
        let slot = match kind.as_str() {
            "exif" | "app1" => &mut meta.exif,
            "xmp" => &mut meta.xmp,
            "icc" | "icm" => &mut meta.icc,
            _ => continue,
        };
        let keyword = format!("Raw profile type {kind}");
        if slot.is_none() {
            match raw_profile(&text) {
                Some(mut v) => {
                    if (kind == "exif" || kind == "app1") && v.starts_with(b"Exif\0\0") {
                        v.drain(..6);
                    }
                    *slot = Some(v);
                }
                None => {
                    meta.problems.push(format!(
                        "PNG: {keyword:?} text is not valid hex; kept as text"
                    ));
                    continue;
                }
            }
        }
        meta.text
            .retain(|t| !t.keyword.eq_ignore_ascii_case(&keyword));
    }
}

/// Append a PNG chunk to `out`: length, type, data, CRC.
pub(crate) fn chunk(out: &mut Vec<u8>, kind: &[u8; 4], data: &[u8]) {
    out.extend_from_slice(&(data.len() as u32).to_be_bytes());
    out.extend_from_slice(kind);
    out.extend_from_slice(data);
    let mut h = crc32fast::Hasher::new();
    h.update(kind);
    h.update(data);
    out.extend_from_slice(&h.finalize().to_be_bytes());
}

fn is_latin1(s: &str) -> bool {
    s.chars().all(|c| (c as u32) < 256)
}

fn text_chunk_bytes(t: &Text) -> Option<([u8; 4], Vec<u8>)> {
    let k = &t.keyword;
    if k.is_empty() || k.chars().count() > 79 || !is_latin1(k) || k.contains('\0') {
        return None;
    }
    let mut data: Vec<u8> = k.chars().map(|c| c as u8).collect();
    data.push(0);
    if is_latin1(&t.text) {
        let text: Vec<u8> = t.text.chars().map(|c| c as u8).collect();
        if text.len() > COMPRESS_ABOVE {
            data.push(0);
            data.extend_from_slice(&deflate(&text));
            Some((*b"zTXt", data))
        } else {
            data.extend_from_slice(&text);
            Some((*b"tEXt", data))
        }
    } else {
        let compress = t.text.len() > COMPRESS_ABOVE;
        data.extend_from_slice(&[compress as u8, 0, 0, 0]);
        if compress {
            data.extend_from_slice(&deflate(t.text.as_bytes()));
        } else {
            data.extend_from_slice(t.text.as_bytes());
        }
        Some((*b"iTXt", data))
    }
}

/// Insert the metadata chunks into `encoded` (a PNG file) right after `IHDR`, as `iCCP`, `eXIf` and the colour
/// chunks must come before the image data.
pub(super) fn embed(meta: &Metadata, encoded: Vec<u8>, dropped: &mut Vec<String>) -> Vec<u8> {
    let ihdr_end = 8 + 8 + 13 + 4;
    if encoded.len() < ihdr_end
        || !encoded.starts_with(b"\x89PNG\r\n\x1a\n")
        || &encoded[12..16] != b"IHDR"
    {
        dropped.push("output is not a PNG stream; metadata not carried".into());
        return encoded;
    }
    let mut chunks = Vec::new();
    if let Some(icc) = &meta.icc {
        let mut data = b"ICC profile\0\0".to_vec();
        data.extend_from_slice(&deflate(icc));
        chunk(&mut chunks, b"iCCP", &data);
    }
    for (kind, data) in &meta.png_chunks {
        chunk(&mut chunks, kind, data);
    }
    if let Some(exif) = &meta.exif {
        match exif_for_output(exif) {
            Ok(e) => chunk(&mut chunks, b"eXIf", &e),
            Err(e) => dropped.push(format!("EXIF block not carried: {e}")),
        }
    }
    if let Some(xmp) = &meta.xmp {
        let mut data = XMP_KEYWORD.as_bytes().to_vec();
        data.extend_from_slice(&[0, 0, 0, 0, 0]);
        data.extend_from_slice(xmp);
        chunk(&mut chunks, b"iTXt", &data);
    }
    for t in &meta.text {
        match text_chunk_bytes(t) {
            Some((kind, data)) => chunk(&mut chunks, &kind, &data),
            None => dropped.push(format!(
                "text with keyword {:?} is not a valid PNG keyword; not carried",
                t.keyword
            )),
        }
    }
    if !meta.xmp_extension.is_empty() {
        dropped.push("JPEG extended-XMP segments have no place in PNG; not carried".into());
    }
    if meta.photoshop.is_some() || meta.iptc.is_some() {
        dropped
            .push("IPTC / Photoshop resources have no standard place in PNG; not carried".into());
    }
    let mut out = Vec::with_capacity(encoded.len() + chunks.len());
    out.extend_from_slice(&encoded[..ihdr_end]);
    out.extend_from_slice(&chunks);
    out.extend_from_slice(&encoded[ihdr_end..]);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Eight zTXt chunks of 20 KB, each inflating to 20 MB (160 MB from a 160 KB file): what is kept stays within
    /// the 64 MiB a file's metadata may take, the rest is named as left out (before: all 160 MB were kept).
    #[test]
    fn many_compressed_texts_are_kept_within_the_budget() {
        let bomb = deflate(&vec![b'a'; 20 << 20]);
        assert!(bomb.len() < 100_000);
        let mut png = b"\x89PNG\r\n\x1a\n".to_vec();
        chunk(&mut png, b"IHDR", &[0, 0, 0, 1, 0, 0, 0, 1, 8, 0, 0, 0, 0]);
        for i in 0..8 {
            let mut data = format!("Comment{i}\0\0").into_bytes();
            data.extend_from_slice(&bomb);
            chunk(&mut png, b"zTXt", &data);
        }
        chunk(&mut png, b"IEND", b"");
        let mut meta = Metadata::default();
        read(std::io::Cursor::new(png), &mut meta);
        let kept: usize = meta.text.iter().map(|t| t.text.len()).sum();
        assert!(kept <= MAX_CHUNK as usize, "{kept} bytes of text kept");
        assert_eq!(meta.text.len(), 3, "{:?}", meta.problems);
        assert!(
            meta.problems.iter().any(|p| p.contains("zTXt")),
            "{:?}",
            meta.problems
        );
    }
}
