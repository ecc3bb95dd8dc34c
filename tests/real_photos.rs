//! Checks on the real underwater photos in `../shared/data/real/` (beside the project). Users' clones do not have
//! them: these tests then say so and pass without checking anything.

use std::path::PathBuf;

fn real_data() -> Option<PathBuf> {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data/real");
    if p.is_dir() {
        Some(p)
    } else {
        eprintln!(
            "skipped: {} is absent (real photos are not shipped with abysslight)",
            p.display()
        );
        None
    }
}

/// The strict JPEG decoding that rejects truncated files must accept every real camera JPEG, with the same pixels
/// as the lenient decoder.
#[test]
fn strict_jpeg_decoding_accepts_real_photos() {
    let Some(dir) = real_data() else { return };
    let found = abysslight::io::find_photos(&dir).unwrap();
    let mut checked = 0;
    for e in found.photos.iter().filter(|e| {
        let ext = e.path.extension().unwrap().to_string_lossy().to_lowercase();
        ext == "jpg" || ext == "jpeg"
    }) {
        let strict = abysslight::io::decode(&e.path).unwrap_or_else(|err| panic!("{err}"));
        let lenient = abysslight::io::photo_from_dynamic(image::open(&e.path).unwrap()).unwrap();
        assert_eq!(strict.layout, lenient.layout, "{}", e.path.display());
        assert!(
            strict.samples == lenient.samples,
            "{}: pixels differ",
            e.path.display()
        );
        checked += 1;
    }
    eprintln!("{checked} real JPEGs decode strictly, identical to lenient decoding");
    assert!(checked > 100);
}
