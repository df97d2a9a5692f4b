//! The shipped `config/plate.csv` is the default plate design, byte for byte.
//! Refresh with `PHOTOPOSE_BLESS=1 cargo test -p photopose-field`.

// The test reads the shipped file: IO belongs to the test, not the crate.
#![allow(clippy::disallowed_types, clippy::disallowed_methods)]

use photopose_field::design::default_plate;
use photopose_field::Field;

#[test]
fn shipped_plate_is_the_default_design() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../config/plate.csv");
    let want = default_plate().to_csv();
    if std::env::var_os("PHOTOPOSE_BLESS").is_some() {
        std::fs::write(path, &want).unwrap();
    }
    let have = std::fs::read_to_string(path).expect("config/plate.csv is shipped");
    assert_eq!(
        have, want,
        "config/plate.csv differs from the default design"
    );
    Field::parse_csv(&have, path).unwrap();
}
