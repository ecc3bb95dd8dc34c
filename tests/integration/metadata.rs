//! Metadata through the whole pipeline: small missions of JPEG, PNG and TIFF photos carrying EXIF (camera, focal
//! length, time, GPS, orientation), XMP and an ICC profile, made by independent encoders (jpeg-encoder, png,
//! tiff, kamadak-exif); after `correct_mission`, the tags are read back from each output by independent readers
//! (kamadak-exif, image's decoders) and must be that photo's own.

use std::io::{BufReader, Cursor};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use abysslight::{correct_mission, Error, Metadata, Options, Progress};
use exif::{Field, In, Rational, Tag, Value};
use image::metadata::Orientation;
use image::ImageDecoder;

const W: usize = 48;
const H: usize = 32;
/// Survey photos per mission: 4 with metadata, 1 without, 1 with a malformed block.
const PHOTOS: usize = 6;
const ORIENTATIONS: [u16; 4] = [1, 6, 8, 3];

/// What photo `i` of a mission carries.
struct Shot {
    date: String,
    lat_minutes: u32,
    orientation: u16,
    xmp: String,
}

fn shot(i: usize) -> Shot {
    Shot {
        date: format!("2024:05:06 07:08:{:02}", 10 + i),
        lat_minutes: 30 + i as u32,
        orientation: ORIENTATIONS[i % 4],
        xmp: format!(
            r#"<?xpacket begin="" id="W5M0MpCehiHzreSzNTczkc9d"?><x:xmpmeta xmlns:x="adobe:ns:meta/"><rdf:RDF xmlns:rdf="http://www.w3.org/1999/02/22-rdf-syntax-ns#"><rdf:Description rdf:about="" xmlns:auv="http://example.org/auv/1.0/" auv:Frame="{i}" auv:Depth="4123.5"/></rdf:RDF></x:xmpmeta><?xpacket end="w"?>"#
        ),
    }
}

fn icc() -> Vec<u8> {
    let mut v: Vec<u8> = (0..3000).map(|i| (i * 13 % 251) as u8).collect();
    v[..4].copy_from_slice(&3000u32.to_be_bytes());
    // A valid header as far as abysslight looks: RGB data (profiles of another colour space are dropped).
    v[16..20].copy_from_slice(b"RGB ");
    v[36..40].copy_from_slice(b"acsp");
    v
}

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

/// The EXIF block of a shot, written by kamadak-exif.
fn exif_blob(s: &Shot) -> Vec<u8> {
    let p = In::PRIMARY;
    let f = |tag, value| Field {
        tag,
        ifd_num: p,
        value,
    };
    let fields = [
        f(Tag::Make, ascii("Abyss Optics")),
        f(Tag::Model, ascii("SeaCam 3000")),
        f(Tag::Orientation, Value::Short(vec![s.orientation])),
        f(Tag::DateTimeOriginal, ascii(&s.date)),
        f(Tag::FocalLength, rationals(&[(125, 10)])),
        f(Tag::GPSLatitudeRef, ascii("S")),
        f(
            Tag::GPSLatitude,
            rationals(&[(12, 1), (s.lat_minutes, 1), (5678, 100)]),
        ),
        f(Tag::GPSAltitudeRef, Value::Byte(vec![1])),
        f(Tag::GPSAltitude, rationals(&[(41235, 10)])),
    ];
    let mut w = exif::experimental::Writer::new();
    for x in &fields {
        w.push_field(x);
    }
    let mut c = Cursor::new(Vec::new());
    w.write(&mut c, true).unwrap();
    c.into_inner()
}

/// Photo `i`: a smooth pattern under a light cone, different per photo.
fn pixels(i: usize) -> Vec<f32> {
    let mut v = Vec::with_capacity(W * H * 3);
    for y in 0..H {
        for x in 0..W {
            let d = ((x as f32 - 24.0) / 30.0).powi(2) + ((y as f32 - 16.0) / 20.0).powi(2);
            let light = 0.3 + 0.7 * (-d).exp();
            for c in 0..3 {
                let albedo = 0.4
                    + 0.2 * (((x + 3 * i) as f32 * 0.3 + c as f32).sin() * (y as f32 * 0.2).cos());
                v.push(light * albedo);
            }
        }
    }
    v
}

fn to8(v: &[f32]) -> Vec<u8> {
    v.iter().map(|x| (x * 255.0).round() as u8).collect()
}

fn to16(v: &[f32]) -> Vec<u16> {
    v.iter().map(|x| (x * 65535.0).round() as u16).collect()
}

/// How a photo's metadata is broken (or not there).
#[derive(Clone, Copy, PartialEq)]
enum Meta {
    Good,
    None,
    Broken,
}

fn jpeg(i: usize, meta: Meta) -> Vec<u8> {
    let s = shot(i);
    let mut out = Vec::new();
    let mut enc = jpeg_encoder::Encoder::new(&mut out, 92);
    if meta != Meta::None {
        enc.add_app_segment(1, [&b"Exif\0\0"[..], &exif_blob(&s)].concat())
            .unwrap();
    }
    match meta {
        Meta::Good => {
            enc.add_app_segment(
                1,
                [&b"http://ns.adobe.com/xap/1.0/\0"[..], s.xmp.as_bytes()].concat(),
            )
            .unwrap();
            enc.add_icc_profile(&icc()).unwrap();
        }
        // The first of two ICC chunks only.
        Meta::Broken => enc
            .add_app_segment(2, [&b"ICC_PROFILE\0\x01\x02"[..], &icc()].concat())
            .unwrap(),
        Meta::None => {}
    }
    enc.encode(
        &to8(&pixels(i)),
        W as u16,
        H as u16,
        jpeg_encoder::ColorType::Rgb,
    )
    .unwrap();
    out
}

fn png16(i: usize, meta: Meta) -> Vec<u8> {
    let s = shot(i);
    let mut out = Vec::new();
    let mut info = png::Info::with_size(W as u32, H as u32);
    info.color_type = png::ColorType::Rgb;
    info.bit_depth = png::BitDepth::Sixteen;
    if meta != Meta::None {
        info.exif_metadata = Some(exif_blob(&s).into());
    }
    if meta == Meta::Good {
        info.icc_profile = Some(icc().into());
    }
    let mut enc = png::Encoder::with_info(&mut out, info).unwrap();
    if meta == Meta::Good {
        enc.add_itxt_chunk("XML:com.adobe.xmp".into(), s.xmp.clone())
            .unwrap();
    }
    let mut w = enc.write_header().unwrap();
    if meta == Meta::Broken {
        w.write_chunk(png::chunk::ChunkType(*b"zTXt"), b"Note\0\0not zlib data")
            .unwrap();
    }
    let be: Vec<u8> = to16(&pixels(i))
        .iter()
        .flat_map(|v| v.to_be_bytes())
        .collect();
    w.write_image_data(&be).unwrap();
    w.finish().unwrap();
    out
}

fn tiff16(i: usize, meta: Meta) -> Vec<u8> {
    use tiff::encoder::{colortype::RGB16, Rational as R, TiffEncoder};
    use tiff::tags::Tag as T;
    let s = shot(i);
    let mut out = Cursor::new(Vec::new());
    let mut enc = TiffEncoder::new(&mut out).unwrap();
    let mut pointers = Vec::new();
    if meta == Meta::Good {
        let mut d = enc.extra_directory().unwrap();
        d.write_tag(T::Unknown(0x9003), s.date.as_str()).unwrap();
        d.write_tag(T::Unknown(0x920a), R { n: 125, d: 10 })
            .unwrap();
        pointers.push((T::ExifDirectory, d.finish_with_offsets().unwrap().offset));
        let mut d = enc.extra_directory().unwrap();
        d.write_tag(T::Unknown(1), "S").unwrap();
        let lat = [
            R { n: 12, d: 1 },
            R {
                n: s.lat_minutes,
                d: 1,
            },
            R { n: 5678, d: 100 },
        ];
        d.write_tag(T::Unknown(2), lat).unwrap();
        pointers.push((T::GpsDirectory, d.finish_with_offsets().unwrap().offset));
    }
    let data = to16(&pixels(i));
    let mut img = enc.new_image::<RGB16>(W as u32, H as u32).unwrap();
    if meta != Meta::None {
        let e = img.encoder();
        e.write_tag(T::Make, "Abyss Optics").unwrap();
        e.write_tag(T::Model, "SeaCam 3000").unwrap();
        e.write_tag(T::Orientation, s.orientation).unwrap();
        for (tag, at) in pointers {
            e.write_tag(tag, at).unwrap();
        }
        if meta == Meta::Good {
            e.write_tag(T::Unknown(700), s.xmp.as_bytes()).unwrap();
            e.write_tag(T::IccProfile, &icc()[..]).unwrap();
        } else {
            // An EXIF pointer past the end of the file.
            e.write_tag(T::ExifDirectory, 50_000_000u32).unwrap();
        }
    }
    img.write_data(&data).unwrap();
    out.into_inner()
}

#[derive(Default)]
struct Recorder {
    warnings: Mutex<Vec<String>>,
    errors: Mutex<Vec<String>>,
}

impl Progress for Recorder {
    fn warn(&self, m: &str) {
        self.warnings.lock().unwrap().push(m.to_string());
    }
    fn stage(&self, _: &str) {}
    fn file_error(&self, e: &Error) {
        self.errors.lock().unwrap().push(e.to_string());
    }
    fn start(&self, _: usize) {}
    fn photo_done(&self, _: &Path, _: bool) {}
    fn finish(&self) {}
}

fn name(i: usize, ext: &str) -> String {
    format!("photo_{i}.{ext}")
}

/// Run a mission of [`PHOTOS`] photos made by `make`; returns the output folder and the warnings.
fn run_mission(d: &Path, ext: &str, make: fn(usize, Meta) -> Vec<u8>) -> (PathBuf, Vec<String>) {
    let survey = d.join(format!("survey_{ext}"));
    std::fs::create_dir_all(&survey).unwrap();
    for i in 0..PHOTOS {
        let meta = match i {
            4 => Meta::None,
            5 => Meta::Broken,
            _ => Meta::Good,
        };
        std::fs::write(survey.join(name(i, ext)), make(i, meta)).unwrap();
    }
    let out = d.join(format!("out_{ext}"));
    let opts = Options {
        survey: Some(survey),
        out: Some(out.clone()),
        window: Some(3),
        ..Options::default()
    };
    let rec = Recorder::default();
    let report = correct_mission(&opts, &rec).unwrap();
    assert!(rec.errors.lock().unwrap().is_empty(), "{:?}", rec.errors);
    assert_eq!((report.corrected, report.failed), (PHOTOS, 0));
    let warnings = rec.warnings.into_inner().unwrap();
    (out, warnings)
}

fn exif_of(path: &Path) -> exif::Exif {
    let f = std::fs::File::open(path).unwrap();
    exif::Reader::new()
        .read_from_container(&mut BufReader::new(f))
        .unwrap_or_else(|e| panic!("{}: no EXIF: {e}", path.display()))
}

fn text(exif: &exif::Exif, tag: Tag) -> Option<String> {
    match &exif.get_field(tag, In::PRIMARY)?.value {
        Value::Ascii(v) => Some(String::from_utf8_lossy(&v[0]).into_owned()),
        _ => None,
    }
}

fn rats(exif: &exif::Exif, tag: Tag) -> Option<Vec<(u32, u32)>> {
    match &exif.get_field(tag, In::PRIMARY)?.value {
        Value::Rational(v) => Some(v.iter().map(|r| (r.num, r.denom)).collect()),
        _ => None,
    }
}

/// image's decoder for a file. TIFF directly: through `ImageReader`, image gives the tiff crate a tag-size limit
/// equal to the pixel buffer, which a 3000-byte profile exceeds in these tiny photos, and then reports no profile
/// (for the inputs as well).
fn decoder(path: &Path) -> Box<dyn ImageDecoder> {
    if path.extension().is_some_and(|e| e == "tif") {
        let f = BufReader::new(std::fs::File::open(path).unwrap());
        return Box::new(image::codecs::tiff::TiffDecoder::new(f).unwrap());
    }
    Box::new(
        image::ImageReader::open(path)
            .unwrap()
            .with_guessed_format()
            .unwrap()
            .into_decoder()
            .unwrap(),
    )
}

/// Check that every output carries its own input's tags, and that only the broken photo warned.
fn check_mission(out: &Path, ext: &str, warnings: &[String], broken: &str) {
    for i in 0..4 {
        let s = shot(i);
        let p = out.join(name(i, ext));
        let exif = exif_of(&p);
        assert_eq!(
            text(&exif, Tag::Model).as_deref(),
            Some("SeaCam 3000"),
            "{}",
            p.display()
        );
        assert_eq!(
            text(&exif, Tag::DateTimeOriginal),
            Some(s.date.clone()),
            "{}",
            p.display()
        );
        assert_eq!(rats(&exif, Tag::FocalLength), Some(vec![(125, 10)]));
        assert_eq!(text(&exif, Tag::GPSLatitudeRef).as_deref(), Some("S"));
        assert_eq!(
            rats(&exif, Tag::GPSLatitude),
            Some(vec![(12, 1), (s.lat_minutes, 1), (5678, 100)]),
            "{}",
            p.display()
        );
        let o = exif
            .get_field(Tag::Orientation, In::PRIMARY)
            .and_then(|f| f.value.get_uint(0));
        assert_eq!(o, Some(s.orientation as u32), "{}", p.display());
        assert_eq!(exif.get_field(Tag::Make, In::THUMBNAIL).map(|_| ()), None);

        let mut dec = decoder(&p);
        assert_eq!(dec.icc_profile().unwrap(), Some(icc()), "{}", p.display());
        assert_eq!(
            dec.xmp_metadata().unwrap(),
            Some(s.xmp.into_bytes()),
            "{}",
            p.display()
        );
        assert_eq!(
            dec.orientation().unwrap(),
            Orientation::from_exif(s.orientation as u8).unwrap()
        );
        // Pixels stay in stored order: a viewer rotates the output as it rotates the input.
        assert_eq!(dec.dimensions(), (W as u32, H as u32));
        let meta = Metadata::read(&p).unwrap();
        assert!(
            meta.problems.is_empty(),
            "{}: {:?}",
            p.display(),
            meta.problems
        );
    }
    // The photo without metadata gets none (no camera tags appear from elsewhere).
    let none = Metadata::read(&out.join(name(4, ext))).unwrap();
    assert!(none.xmp.is_none() && none.icc.is_none());
    assert!(
        none.exif.is_none()
            || exif_of(&out.join(name(4, ext)))
                .get_field(Tag::Model, In::PRIMARY)
                .is_none()
    );
    // The broken photo is written, with what could be read, and is the only one warned about.
    let p5 = out.join(name(5, ext));
    assert_eq!(
        text(&exif_of(&p5), Tag::Model).as_deref(),
        Some("SeaCam 3000")
    );
    assert_eq!(decoder(&p5).icc_profile().unwrap(), None);
    let meta_warnings: Vec<&String> = warnings.iter().filter(|w| w.contains("metadata")).collect();
    assert_eq!(meta_warnings.len(), 1, "{warnings:?}");
    let w = meta_warnings[0];
    assert!(w.contains(&name(5, ext)) && w.contains(broken), "{w}");
}

#[test]
fn jpeg_mission_carries_each_photos_metadata() {
    let d = tempfile::tempdir().unwrap();
    let (out, warnings) = run_mission(d.path(), "jpg", jpeg);
    check_mission(&out, "jpg", &warnings, "ICC");
}

#[test]
fn png_mission_carries_each_photos_metadata() {
    let d = tempfile::tempdir().unwrap();
    let (out, warnings) = run_mission(d.path(), "png", png16);
    check_mission(&out, "png", &warnings, "zTXt");
    // 16 bits in, 16 bits out.
    assert_eq!(
        decoder(&out.join(name(0, "png"))).color_type(),
        image::ColorType::Rgb16
    );
}

#[test]
fn tiff_mission_carries_each_photos_metadata() {
    let d = tempfile::tempdir().unwrap();
    let (out, warnings) = run_mission(d.path(), "tif", tiff16);
    check_mission(&out, "tif", &warnings, "0x8769");
    assert_eq!(
        decoder(&out.join(name(0, "tif"))).color_type(),
        image::ColorType::Rgb16
    );
}
