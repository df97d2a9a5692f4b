//! Parsing of a pose given on the command line as `X,Y,Z,A,B,C`: the camera's
//! pose in the field frame, KUKA convention (mm, degrees, `M = Rz(A) Ry(B) Rx(C)`).

use anyhow::{bail, Result};

/// Parses `X,Y,Z,A,B,C` into six finite numbers.
pub fn parse_pose(text: &str) -> Result<[f64; 6]> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    if parts.len() != 6 {
        bail!(
            "--pose `{text}`: expected six comma-separated numbers X,Y,Z,A,B,C (mm, degrees), found {}",
            parts.len()
        );
    }
    let mut out = [0.0; 6];
    for (k, (slot, p)) in out.iter_mut().zip(&parts).enumerate() {
        let name = ["X", "Y", "Z", "A", "B", "C"][k];
        match p.parse::<f64>() {
            Ok(v) if v.is_finite() => *slot = v,
            _ => bail!("--pose `{text}`: {name} = `{p}` is not a finite number"),
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strict_parsing() {
        assert_eq!(
            parse_pose("0, 0,1000,0,0,-90").unwrap(),
            [0.0, 0.0, 1000.0, 0.0, 0.0, -90.0]
        );
        assert!(parse_pose("0,0,1000").is_err());
        assert!(parse_pose("0,0,1000,0,0,x")
            .unwrap_err()
            .to_string()
            .contains("C = `x`"));
        assert!(parse_pose("0,0,NaN,0,0,0").is_err());
    }
}
