//! A large field file (100 000 rows) parses in time linear in its length:
//! well under a second in an optimised build, a few seconds at most here.

// A timing test: the clock is the test's, not the crate's.
#![allow(clippy::disallowed_types, clippy::disallowed_methods)]

use photopose_field::{Field, FieldError};
use std::fmt::Write as _;
use std::time::{Duration, Instant};

const ROWS: u64 = 100_000;

fn big_field_csv(rows: u64) -> String {
    let mut s = String::from("id,x,y,z,kind,radius\n# generated grid\n");
    for k in 0..rows {
        let (i, j) = (k % 400, k / 400);
        if k < 30 {
            let _ = writeln!(
                s,
                "{},{},{},0.0,coded,2.0",
                k + 1,
                i as f64 * 20.0,
                j as f64 * 20.0
            );
        } else {
            let _ = writeln!(
                s,
                "{},{},{},0.0,uncoded,1.5",
                1000 + k,
                i as f64 * 20.0,
                j as f64 * 20.0
            );
        }
    }
    s
}

#[test]
fn a_100_000_row_field_parses_quickly_and_correctly() {
    let text = big_field_csv(ROWS);
    let started = Instant::now();
    let field = Field::parse_csv(&text, "big.csv").unwrap();
    let took = started.elapsed();
    assert_eq!(field.len(), ROWS as usize);
    assert_eq!(field.coded().count(), 30);
    let last = field.get(1000 + ROWS - 1).unwrap();
    assert_eq!(last.position.x, ((ROWS - 1) % 400) as f64 * 20.0);
    assert_eq!(field.index_of(1000 + ROWS - 1), Some(ROWS as usize - 1));
    // Generous: a quadratic parser takes minutes here.
    assert!(took < Duration::from_secs(5), "parsing took {took:?}");
}

#[test]
fn a_duplicate_at_the_end_of_a_large_field_names_both_rows() {
    let mut text = big_field_csv(ROWS);
    text.push_str("1030,1.0,2.0,0.0,uncoded,1.5\n");
    let started = Instant::now();
    let e = Field::parse_csv(&text, "big.csv").unwrap_err();
    assert!(started.elapsed() < Duration::from_secs(5));
    match &e {
        FieldError::Row { line, what, .. } => {
            // header + comment + 100 000 rows, then the duplicate.
            assert_eq!(*line, ROWS as usize + 3, "{e}");
            assert!(
                what.contains("duplicate id 1030 (first on data row 31)"),
                "{e}"
            );
        }
        other => panic!("{other}"),
    }
}
