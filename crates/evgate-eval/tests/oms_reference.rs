//! OMS against its reference implementation: a worked example computed by the authors' code
//! (`tests/data/make_oms_reference.py` runs it; the fixture names the commit) gives the same
//! normalised response and the same mask here.

use evgate_core::{Event, SensorSize};
use evgate_eval::oms::{event_presence, normalised_response, oms_mask, OmsParameters};

fn fixture() -> serde_json::Value {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/data/oms_reference_worked_example.json"
    );
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

fn rows(value: &serde_json::Value) -> Vec<Vec<bool>> {
    value
        .as_array()
        .unwrap()
        .iter()
        .map(|row| row.as_str().unwrap().chars().map(|c| c == '1').collect())
        .collect()
}

#[test]
fn oms_matches_the_reference_implementation_on_a_worked_example() {
    let example = fixture();
    let size = SensorSize::new(
        example["width"].as_u64().unwrap() as u16,
        example["height"].as_u64().unwrap() as u16,
    );
    let parameters = OmsParameters {
        centre_radius: example["centre-radius"].as_u64().unwrap() as u32,
        surround_radius: example["surround-radius"].as_u64().unwrap() as u32,
        threshold: example["threshold"].as_f64().unwrap() as f32,
    };
    assert_eq!(parameters, OmsParameters::PUBLISHED_EVIMO);
    let events: Vec<Event> = rows(&example["presence"])
        .iter()
        .enumerate()
        .flat_map(|(y, row)| {
            row.iter()
                .enumerate()
                .filter(|(_, &fired)| fired)
                .map(move |(x, _)| Event::new(0, x as u16, y as u16, true))
        })
        .collect();

    let response = normalised_response(
        &event_presence(&events, size),
        size,
        parameters.centre_radius,
        parameters.surround_radius,
    );
    for (y, row) in example["response"].as_array().unwrap().iter().enumerate() {
        for (x, expected) in row.as_array().unwrap().iter().enumerate() {
            let ours = response[size.index(x as u16, y as u16)] as f64;
            let expected = expected.as_f64().unwrap();
            assert!(
                (ours - expected).abs() < 2e-6,
                "response at ({x}, {y}): {ours} here, {expected} in the reference"
            );
        }
    }

    let mask = oms_mask(&events, size, &parameters);
    let expected = rows(&example["mask"]);
    let flagged = expected.iter().flatten().filter(|&&m| m).count();
    assert!(flagged > 0, "the worked example flags something");
    for (y, row) in expected.iter().enumerate() {
        for (x, &flag) in row.iter().enumerate() {
            assert_eq!(
                mask[size.index(x as u16, y as u16)],
                flag,
                "mask at ({x}, {y})"
            );
        }
    }
}
