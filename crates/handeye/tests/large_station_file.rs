//! A large station file parses in time linear in its length: duplicate
//! station names are found with a map, not by scanning the rows so far.

// A timing test: the clock is the test's, not the crate's.
#![allow(clippy::disallowed_types, clippy::disallowed_methods)]

use photopose_handeye::parse_stations;
use std::fmt::Write as _;
use std::time::{Duration, Instant};

const ROWS: usize = 100_000;

fn stations(rows: usize) -> String {
    let mut s = String::from("station,robot_x,robot_y,robot_z,robot_a,robot_b,robot_c,image\n");
    for k in 0..rows {
        let _ = writeln!(
            s,
            "s{k:06},{}.5,-120.0,655.1,172.0,-3.5,178.2,f{k}.pgm",
            800 + k % 50
        );
    }
    s
}

#[test]
fn a_100_000_row_station_file_parses_quickly_and_finds_a_late_duplicate() {
    let text = stations(ROWS);
    let started = Instant::now();
    let rows = parse_stations(&text, "big.csv").unwrap();
    assert_eq!(rows.len(), ROWS);
    assert_eq!(rows[ROWS - 1].name, format!("s{:06}", ROWS - 1));
    let mut dup = text.clone();
    dup.push_str("s000007,1.0,2.0,3.0,0.0,0.0,0.0,x.pgm\n");
    let e = parse_stations(&dup, "big.csv").unwrap_err().to_string();
    assert!(
        e.contains(&format!("big.csv:{}", ROWS + 2))
            && e.contains("station `s000007` is also on line 9"),
        "{e}"
    );
    // Generous: scanning the rows so far per row takes far longer.
    let took = started.elapsed();
    assert!(took < Duration::from_secs(5), "parsing took {took:?}");
}
