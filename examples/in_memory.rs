//! The method as a library, without files: simulate a small dive in memory, correct it with the [`Engine`], and
//! score the corrected photos against the simulator's true albedo.
//!
//! ```sh
//! cargo run --release --example in_memory
//! ```

use abysslight::eval::evaluate::albedo_error;
use abysslight::eval::simulate::Simulation;
use abysslight::Scatter;
use abysslight::{Engine, Params};
use abysslight::{Photo, Raster};

fn main() -> Result<(), abysslight::Error> {
    let sim = Simulation {
        frames: 20,
        width: 240,
        height: 180,
        seed: 7,
        ..Simulation::default()
    };
    let dive = sim.render()?;

    // S from the water-column frames, then every survey photo through the method with its defaults (the window
    // chosen per stretch by the engine's survey, as `abysslight correct` chooses it).
    let scatter = Scatter::from_frames(&dive.water)?;
    let mut engine = Engine::new(Params::default(), scatter.as_ref(), None)?;
    let mut corrected: Vec<(usize, Photo)> = Vec::new();
    for (i, photo) in dive.survey.iter().cloned().enumerate() {
        for c in engine.push((photo, i))? {
            corrected.extend(c.photo.map(|p| (c.tag, p)));
        }
    }
    for c in engine.finish() {
        corrected.extend(c.photo.map(|p| (c.tag, p)));
    }
    assert_eq!(
        corrected.len(),
        dive.survey.len(),
        "every photo comes out once"
    );
    assert!(
        corrected.windows(2).all(|w| w[0].0 + 1 == w[1].0),
        "in order"
    );

    let raw: Vec<Raster> = dive.survey.iter().map(Raster::from_photo).collect();
    let got: Vec<Raster> = corrected
        .iter()
        .map(|(_, p)| Raster::from_photo(p))
        .collect();
    let before = albedo_error(&raw, &dive.albedo, None);
    let after = albedo_error(&got, &dive.albedo, None);
    println!("albedo error: raw photos {before:.3}, corrected {after:.3}");
    if after >= 0.5 * before {
        eprintln!("the correction did not halve the albedo error");
        std::process::exit(1);
    }
    Ok(())
}
