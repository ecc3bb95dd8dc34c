//! Round trips per format: metadata embedded into a freshly encoded photo, read back by this module and by
//! independent readers (kamadak-exif for EXIF; image's JPEG, PNG and TIFF decoders, i.e. zune-jpeg, png and tiff,
//! for ICC, XMP and pixels).

use std::collections::BTreeMap;
use std::io::Cursor;

use exif::{Field, In, Rational, Tag, Value};
use image::ImageDecoder;

use super::ifd::Order;
use super::*;
use crate::method::raster::{Layout, Samples};

const XMP: &str = r#"<?xpacket begin="" id="W5M0MpCehiHzreSzNTczkc9d"?><x:xmpmeta xmlns:x="adobe:ns:meta/"><rdf:RDF xmlns:rdf="http://www.w3.org/1999/02/22-rdf-syntax-ns#"><rdf:Description rdf:about="" xmlns:tiff="http://ns.adobe.com/tiff/1.0/" xmlns:auv="http://example.org/auv/1.0/" tiff:Orientation="6" auv:Depth="4123.5" auv:Heading="271.25"/></rdf:RDF></x:xmpmeta><?xpacket end="w"?>"#;
const THUMB: &[u8] = b"\xff\xd8\xff\xdbthe uncorrected photo, small\xff\xd9";

fn ascii(s: &str) -> Value {
    Value::Ascii(vec![s.as_bytes().to_vec()])
}

fn rationals(v: &[(u32, u32)]) -> Value {
    Value::Rational(
        v.iter()
            .map(|&(num, denom)| Rational { num, denom })
            .collect(),
    )
}

fn field(tag: Tag, ifd: In, value: Value) -> Field {
    Field {
        tag,
        ifd_num: ifd,
        value,
    }
}

/// What a survey camera writes: camera, lens, time, orientation, position and depth, a maker note.
fn camera_fields() -> Vec<Field> {
    let p = In::PRIMARY;
    vec![
        field(Tag::Make, p, ascii("Abyss Optics")),
        field(Tag::Model, p, ascii("SeaCam 3000")),
        field(Tag::Orientation, p, Value::Short(vec![6])),
        field(Tag::XResolution, p, rationals(&[(300, 1)])),
        field(Tag::YResolution, p, rationals(&[(300, 1)])),
        field(Tag::ResolutionUnit, p, Value::Short(vec![2])),
        field(Tag::DateTime, p, ascii("2024:05:06 07:08:09")),
        field(Tag::ExifVersion, p, Value::Undefined(b"0232".to_vec(), 0)),
        field(Tag::DateTimeOriginal, p, ascii("2024:05:06 07:08:09")),
        field(Tag::FocalLength, p, rationals(&[(125, 10)])),
        field(Tag::ExposureTime, p, rationals(&[(1, 250)])),
        field(
            Tag::MakerNote,
            p,
            Value::Undefined(b"ABYSS\0\x01\x02\x03\x04".to_vec(), 0),
        ),
        field(Tag::GPSLatitudeRef, p, ascii("S")),
        field(
            Tag::GPSLatitude,
            p,
            rationals(&[(12, 1), (34, 1), (5678, 100)]),
        ),
        field(Tag::GPSLongitudeRef, p, ascii("W")),
        field(
            Tag::GPSLongitude,
            p,
            rationals(&[(123, 1), (4, 1), (500, 100)]),
        ),
        field(Tag::GPSAltitudeRef, p, Value::Byte(vec![1])),
        field(Tag::GPSAltitude, p, rationals(&[(41235, 10)])),
        field(Tag::GPSImgDirectionRef, p, ascii("T")),
        field(Tag::GPSImgDirection, p, rationals(&[(27125, 100)])),
        field(Tag::InteroperabilityIndex, p, ascii("R98")),
    ]
}

fn exif_blob(fields: &[Field], thumbnail: Option<&[u8]>, little_endian: bool) -> Vec<u8> {
    let mut w = exif::experimental::Writer::new();
    for f in fields {
        w.push_field(f);
    }
    if let Some(t) = thumbnail {
        w.set_jpeg(t, In::THUMBNAIL);
    }
    let mut c = Cursor::new(Vec::new());
    w.write(&mut c, little_endian).unwrap();
    c.into_inner()
}

/// Fields as (tag name, IFD number) -> value, without the IFD pointers (their values are layout).
fn fields(exif: &exif::Exif) -> BTreeMap<(String, u16), String> {
    exif.fields()
        .filter(|f| {
            !matches!(
                f.tag,
                Tag::ExifIFDPointer | Tag::GPSInfoIFDPointer | Tag::InteropIFDPointer
            )
        })
        .map(|f| {
            let v = match &f.value {
                Value::Undefined(v, _) => format!("Undefined({v:?})"),
                v => format!("{v:?}"),
            };
            ((f.tag.to_string(), f.ifd_num.index()), v)
        })
        .collect()
}

fn expected_fields() -> BTreeMap<(String, u16), String> {
    let blob = exif_blob(&camera_fields(), None, true);
    fields(&exif::Reader::new().read_raw(blob).unwrap())
}

/// A profile-shaped blob larger than one JPEG segment (forces several APP2 chunks).
fn icc(len: usize) -> Vec<u8> {
    let mut v: Vec<u8> = (0..len).map(|i| (i * 7 % 251) as u8).collect();
    v[..4].copy_from_slice(&(len as u32).to_be_bytes());
    v[36..40].copy_from_slice(b"acsp");
    v
}

fn photo(sixteen: bool) -> Photo {
    let (w, h) = (24, 16);
    let n = w * h * 3;
    Photo {
        layout: Layout {
            width: w,
            height: h,
            channels: 3,
        },
        samples: if sixteen {
            Samples::U16((0..n).map(|i| (i * 167 % 65536) as u16).collect())
        } else {
            Samples::U8((0..n).map(|i| (i * 7 % 256) as u8).collect())
        },
        alpha: None,
    }
}

fn encode(photo: &Photo, format: ImageFormat) -> Vec<u8> {
    let mut v = Vec::new();
    io::encode_to(photo, format, EncodeSettings::default(), &mut v).unwrap();
    v
}

fn base_meta(little_endian: bool) -> Metadata {
    Metadata {
        exif: Some(exif_blob(&camera_fields(), Some(THUMB), little_endian)),
        xmp: Some(XMP.as_bytes().to_vec()),
        icc: Some(icc(150_000)),
        ..Metadata::default()
    }
}

#[test]
fn jpeg_round_trip() {
    let mut meta = base_meta(true);
    meta.xmp_extension = vec![b"0123456789ABCDEF0123456789ABCDEF\0\0\0\x05\0\0\0\0<rest>".to_vec()];
    let iptc = super::tests::resource(0x0404, "", b"\x1c\x02\x05\x00\x04Dive");
    let thumb = super::tests::resource(0x040c, "", THUMB);
    meta.photoshop = Some([iptc.clone(), thumb].concat());
    meta.text = vec![Text {
        keyword: "Comment".into(),
        text: "Dive 42, transect 7 — Ω".into(),
    }];
    let (out, dropped) = meta.embed(ImageFormat::Jpeg, encode(&photo(false), ImageFormat::Jpeg));
    assert!(dropped.is_empty(), "{dropped:?}");

    // Read back by this module: everything, with the thumbnail taken out of the EXIF block.
    let back = Metadata::from_bytes(&out).unwrap();
    assert!(back.problems.is_empty(), "{:?}", back.problems);
    let stripped = exif_for_output(meta.exif.as_ref().unwrap()).unwrap();
    assert!(stripped.len() < meta.exif.as_ref().unwrap().len());
    assert_eq!(
        back,
        Metadata {
            exif: Some(stripped.clone()),
            photoshop: Some(iptc.clone()),
            ..meta.clone()
        }
    );
    assert_eq!(back.orientation(), Some(6));
    // The Photoshop resources (which hold IPTC), as image's JPEG decoder finds them: without the thumbnail.
    let mut dec = image::codecs::jpeg::JpegDecoder::new(Cursor::new(&out)).unwrap();
    assert_eq!(dec.iptc_metadata().unwrap(), Some(iptc));

    // Read back independently.
    let exif = exif::Reader::new()
        .read_from_container(&mut Cursor::new(&out))
        .unwrap();
    assert_eq!(fields(&exif), expected_fields());
    let mut dec = image::codecs::jpeg::JpegDecoder::new(Cursor::new(&out)).unwrap();
    assert_eq!(dec.icc_profile().unwrap(), meta.icc);
    assert_eq!(dec.xmp_metadata().unwrap(), meta.xmp);
    assert_eq!(dec.exif_metadata().unwrap(), Some(stripped));
    assert_eq!(
        dec.orientation().unwrap(),
        image::metadata::Orientation::Rotate90
    );
    // Pixels stay in stored order: not rotated.
    let img = image::load_from_memory(&out).unwrap();
    assert_eq!((img.width(), img.height()), (24, 16));
}

#[test]
fn jpeg_drops_what_does_not_fit_a_segment_and_keeps_the_rest() {
    let mut big = camera_fields();
    big.retain(|f| f.tag != Tag::MakerNote);
    big.push(field(
        Tag::MakerNote,
        In::PRIMARY,
        Value::Undefined(vec![7; 70_000], 0),
    ));
    let meta = Metadata {
        exif: Some(exif_blob(&big, None, false)),
        xmp: Some(vec![b' '; 70_000]),
        icc: Some(icc(1000)),
        png_chunks: vec![(*b"gAMA", vec![0, 0, 0xb1, 0x8f])],
        ..Metadata::default()
    };
    let (out, dropped) = meta.embed(ImageFormat::Jpeg, encode(&photo(false), ImageFormat::Jpeg));
    assert_eq!(dropped.len(), 3, "{dropped:?}");
    assert!(dropped[0].starts_with("EXIF block of") && dropped[1].starts_with("XMP packet of"));
    assert!(dropped[2].contains("PNG"));
    let back = Metadata::from_bytes(&out).unwrap();
    assert_eq!((back.exif, back.xmp, back.icc), (None, None, meta.icc));
}

#[test]
fn png_round_trip() {
    let mut meta = base_meta(false);
    meta.text = vec![
        Text {
            keyword: "Title".into(),
            text: "Transect 7, Clarion-Clipperton Zone".into(),
        },
        Text {
            keyword: "Description".into(),
            text: "x".repeat(5000),
        },
        Text {
            keyword: "Comment".into(),
            text: "Tiefsee — Ω".into(),
        },
    ];
    meta.png_chunks = vec![
        (*b"gAMA", 45455u32.to_be_bytes().to_vec()),
        (
            *b"pHYs",
            [&11811u32.to_be_bytes()[..], &11811u32.to_be_bytes(), &[1]].concat(),
        ),
    ];
    let original = photo(true);
    let (out, dropped) = meta.embed(ImageFormat::Png, encode(&original, ImageFormat::Png));
    assert!(dropped.is_empty(), "{dropped:?}");

    let back = Metadata::from_bytes(&out).unwrap();
    assert!(back.problems.is_empty(), "{:?}", back.problems);
    let stripped = exif_for_output(meta.exif.as_ref().unwrap()).unwrap();
    assert_eq!(
        back,
        Metadata {
            exif: Some(stripped.clone()),
            ..meta.clone()
        }
    );

    // The png crate (which checks every chunk's CRC) reads it all back.
    let mut reader = ::png::Decoder::new(Cursor::new(&out)).read_info().unwrap();
    let info = reader.info();
    assert_eq!(info.icc_profile.as_deref(), meta.icc.as_deref());
    assert_eq!(info.exif_metadata.as_deref(), Some(&stripped[..]));
    assert_eq!(info.gama_chunk.map(|g| g.into_scaled()), Some(45455));
    assert_eq!(info.pixel_dims.map(|p| p.xppu), Some(11811));
    assert_eq!(
        info.uncompressed_latin1_text[0].text,
        "Transect 7, Clarion-Clipperton Zone"
    );
    assert_eq!(info.compressed_latin1_text.len(), 1);
    assert_eq!(info.utf8_text.len(), 2, "XMP and the non-Latin-1 comment");
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    reader.next_frame(&mut buf).unwrap();
    let exif = exif::Reader::new()
        .read_from_container(&mut Cursor::new(&out))
        .unwrap();
    assert_eq!(fields(&exif), expected_fields());
    let mut dec = image::codecs::png::PngDecoder::new(Cursor::new(&out)).unwrap();
    assert_eq!(dec.xmp_metadata().unwrap(), meta.xmp);
    let img = image::load_from_memory(&out).unwrap();
    assert_eq!(io::photo_from_dynamic(img).unwrap(), original);
}

#[test]
fn png_imagemagick_raw_profiles_become_exif() {
    let blob = exif_blob(&camera_fields(), None, true);
    let hex: String = [&b"Exif\0\0"[..], &blob]
        .concat()
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect();
    let text = format!("\nexif\n{:8}\n{}\n", blob.len() + 6, hex);
    let mut file = Vec::new();
    {
        let mut enc = ::png::Encoder::new(&mut file, 2, 2);
        enc.set_color(::png::ColorType::Grayscale);
        enc.add_ztxt_chunk("Raw profile type exif".into(), text)
            .unwrap();
        enc.add_text_chunk("Software".into(), "ImageMagick".into())
            .unwrap();
        enc.write_header()
            .unwrap()
            .write_image_data(&[0; 4])
            .unwrap();
    }
    let meta = Metadata::from_bytes(&file).unwrap();
    assert!(meta.problems.is_empty(), "{:?}", meta.problems);
    assert_eq!(meta.exif, Some(blob));
    assert_eq!(meta.text.len(), 1, "the hex copy is not kept as text");
    assert_eq!(meta.text[0].keyword, "Software");
}

#[test]
fn tiff_round_trip_in_both_byte_orders() {
    for little_endian in [true, false] {
        let mut fields_in = camera_fields();
        // A pixel-layout tag in the EXIF block must not replace the output's own.
        fields_in.push(field(Tag::ImageWidth, In::PRIMARY, Value::Long(vec![9999])));
        let mut meta = base_meta(little_endian);
        meta.exif = Some(exif_blob(&fields_in, Some(THUMB), little_endian));
        meta.iptc = Some(b"\x1c\x02\x05\x00\x04Dive".to_vec());
        meta.photoshop = Some(b"8BIM\x04\x04\0\0\0\0\0\x00".to_vec());
        let original = photo(true);
        let (out, dropped) = meta.embed(ImageFormat::Tiff, encode(&original, ImageFormat::Tiff));
        // The maker note survives when the byte orders agree, and is reported when they do not.
        let native = Order::native() == Order::Little;
        assert_eq!(
            dropped.len(),
            (little_endian != native) as usize,
            "{dropped:?}"
        );

        // Pixels intact (the tiff crate follows the new first IFD to the old strips).
        let img = image::load_from_memory(&out).unwrap();
        assert_eq!(io::photo_from_dynamic(img).unwrap(), original);
        let mut dec = image::codecs::tiff::TiffDecoder::new(Cursor::new(&out)).unwrap();
        assert_eq!(dec.icc_profile().unwrap(), meta.icc);
        assert_eq!(dec.xmp_metadata().unwrap(), meta.xmp);
        assert_eq!(
            dec.orientation().unwrap(),
            image::metadata::Orientation::Rotate90
        );

        // EXIF tags, read by kamadak-exif from the TIFF itself (IFD0 and sub-IFDs).
        let exif = exif::Reader::new()
            .read_from_container(&mut Cursor::new(&out))
            .unwrap();
        let got = fields(&exif);
        let mut want = expected_fields();
        if little_endian != native {
            want.remove(&("MakerNote".to_string(), 0));
        }
        for (k, v) in &want {
            assert_eq!(
                got.get(k),
                Some(v),
                "{k:?} (little endian: {little_endian})"
            );
        }
        assert_eq!(got[&("ImageWidth".to_string(), 0)], "Long([24])");

        // And by this module: the same fields again, plus IPTC and Photoshop resources.
        let back = Metadata::from_bytes(&out).unwrap();
        assert!(back.problems.is_empty(), "{:?}", back.problems);
        assert_eq!((&back.xmp, &back.icc), (&meta.xmp, &meta.icc));
        assert_eq!(&back.photoshop, &meta.photoshop);
        // IPTC is stored as LONGs, so it comes back zero-padded to a multiple of 4 bytes.
        assert_eq!(
            back.iptc.as_deref(),
            Some(&b"\x1c\x02\x05\x00\x04Dive\0\0\0"[..])
        );
        let again = exif::Reader::new()
            .read_raw(back.exif.clone().unwrap())
            .unwrap();
        let again = fields(&again);
        for (k, v) in &want {
            assert_eq!(again.get(k), Some(v), "{k:?}");
        }
        // Only descriptive tags went into the EXIF block of a TIFF input.
        assert!(again
            .keys()
            .all(|(t, _)| !["ImageWidth", "StripOffsets", "BitsPerSample"].contains(&t.as_str())));
    }
}

#[test]
fn tiff_input_without_metadata_gives_empty_metadata_and_unchanged_output() {
    let tiff = encode(&photo(false), ImageFormat::Tiff);
    let meta = Metadata::from_bytes(&tiff).unwrap();
    // The encoder's own resolution placeholders are descriptive tags, so they form a (small) EXIF block.
    assert!(meta.xmp.is_none() && meta.icc.is_none() && meta.problems.is_empty());
    let (out, dropped) = Metadata::default().embed(ImageFormat::Tiff, tiff.clone());
    assert!(dropped.is_empty());
    assert_eq!(out, tiff);
}

#[test]
fn malformed_blocks_are_reported_and_the_rest_is_read() {
    // A JPEG with the first of two ICC chunks only, and a good XMP packet.
    let mut jpeg = Vec::new();
    let mut enc = jpeg_encoder::Encoder::new(&mut jpeg, 90);
    enc.add_app_segment(2, [&b"ICC_PROFILE\0\x01\x02"[..], &[1; 100]].concat())
        .unwrap();
    enc.add_app_segment(
        1,
        [&b"http://ns.adobe.com/xap/1.0/\0"[..], XMP.as_bytes()].concat(),
    )
    .unwrap();
    enc.encode(&[0; 12], 2, 2, jpeg_encoder::ColorType::Rgb)
        .unwrap();
    let meta = Metadata::from_bytes(&jpeg).unwrap();
    assert_eq!(meta.icc, None);
    assert_eq!(meta.xmp.as_deref(), Some(XMP.as_bytes()));
    assert_eq!(meta.problems.len(), 1);
    assert!(meta.problems[0].contains("ICC"), "{:?}", meta.problems);

    // A JPEG cut off in the middle of a segment.
    let cut = Metadata::from_bytes(&jpeg[..40]).unwrap();
    assert!(cut.problems[0].contains("cut off"), "{:?}", cut.problems);

    // A PNG whose zTXt data is not zlib: reported, other text kept.
    let mut png_file = Vec::new();
    {
        let mut enc = ::png::Encoder::new(&mut png_file, 1, 1);
        enc.add_text_chunk("Title".into(), "ok".into()).unwrap();
        let mut w = enc.write_header().unwrap();
        w.write_chunk(::png::chunk::ChunkType(*b"zTXt"), b"Note\0\0not zlib")
            .unwrap();
        w.write_image_data(&[0]).unwrap();
    }
    let meta = Metadata::from_bytes(&png_file).unwrap();
    assert_eq!(meta.text.len(), 1);
    assert!(meta.problems[0].contains("zTXt"), "{:?}", meta.problems);
}

#[test]
fn png_text_after_the_image_data_is_read() {
    let mut file = Vec::new();
    {
        let mut enc = ::png::Encoder::new(&mut file, 4, 4);
        enc.set_color(::png::ColorType::Grayscale);
        let mut w = enc.write_header().unwrap();
        w.write_image_data(&[7; 16]).unwrap();
        let mut data = b"Comment\0".to_vec();
        data.extend_from_slice(b"written after IDAT");
        w.write_chunk(::png::chunk::ChunkType(*b"tEXt"), &data)
            .unwrap();
        w.finish().unwrap();
    }
    let idat = file.windows(4).position(|w| w == b"IDAT").unwrap();
    let text = file.windows(4).position(|w| w == b"tEXt").unwrap();
    assert!(text > idat);
    let meta = Metadata::from_bytes(&file).unwrap();
    assert!(meta.problems.is_empty(), "{:?}", meta.problems);
    assert_eq!(
        meta.text,
        [Text {
            keyword: "Comment".into(),
            text: "written after IDAT".into()
        }]
    );
}
