//! Checks on the real underwater photos in `../shared/data/real/` (beside the project). Users' clones do not have
//! them: these tests are ignored, and `.ci/run` runs them (`cargo test --release -- --ignored`) where the photos
//! are; run so without them, they fail.

use std::path::PathBuf;

fn real_data() -> PathBuf {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data/real");
    assert!(p.is_dir(), "{} is absent", p.display());
    p
}

/// The strict JPEG decoding that rejects truncated files must accept every real camera JPEG, with the same pixels
/// as the lenient decoder.
#[test]
#[ignore = "needs ../shared/data/real beside the project (real photos are not shipped); .ci/run runs it where they are"]
fn strict_jpeg_decoding_accepts_real_photos() {
    let dir = real_data();
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
