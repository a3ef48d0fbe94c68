//! GPS fixes as CSV, the layout of `shared/tools/synth_gps.py`:
//! `keyframe,lat,lon,sigma_east,sigma_north[,true_east,true_north]` with a
//! header line naming the columns (any order; `altitude` optional).

use super::{ReadError, ReadErrorKind};
use crate::gps::Geodetic;
use crate::graph::KeyframeId;
use std::path::Path;

/// One line of a fix file.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FixRecord {
    /// The keyframe the fix belongs to.
    pub keyframe: KeyframeId,
    /// Where the receiver was.
    pub position: Geodetic,
    /// σ east and σ north (m).
    pub sigma: [f64; 2],
    /// The true ENU position, when the file has it (synthetic data).
    pub truth: Option<[f64; 2]>,
}

/// Reads a fix file.
pub fn read_fixes(path: &Path) -> Result<Vec<FixRecord>, ReadError> {
    let text = std::fs::read_to_string(path).map_err(|e| ReadError::io(path, e))?;
    parse_fixes(path, &text)
}

pub(crate) fn parse_fixes(path: &Path, text: &str) -> Result<Vec<FixRecord>, ReadError> {
    let bad = |line: usize, m: String| ReadError::at(path, line, ReadErrorKind::Malformed(m));
    let mut lines = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty() && !l.starts_with('#'));
    let (hline, header) = lines.next().ok_or_else(|| bad(1, "no header line".into()))?;
    let names: Vec<&str> = header.split(',').map(str::trim).collect();
    let col = |name: &str| names.iter().position(|&n| n == name);
    let need =
        |name: &str| col(name).ok_or_else(|| bad(hline + 1, format!("header lacks the `{name}` column")));
    let (k, lat, lon, se, sn) = (
        need("keyframe")?,
        need("lat")?,
        need("lon")?,
        need("sigma_east")?,
        need("sigma_north")?,
    );
    let (te, tn, alt) = (col("true_east"), col("true_north"), col("altitude"));
    let mut out = Vec::new();
    for (n, line) in lines {
        let fields: Vec<&str> = line.split(',').map(str::trim).collect();
        if fields.len() != names.len() {
            return Err(bad(
                n + 1,
                format!("{} fields where the header has {}", fields.len(), names.len()),
            ));
        }
        let num = |i: usize| -> Result<f64, ReadError> {
            let v: f64 = fields[i]
                .parse()
                .map_err(|_| bad(n + 1, format!("`{}` is not a number", fields[i])))?;
            if v.is_finite() {
                Ok(v)
            } else {
                Err(bad(n + 1, format!("non-finite number `{}`", fields[i])))
            }
        };
        let keyframe = fields[k]
            .parse()
            .map_err(|_| bad(n + 1, format!("`{}` is not a keyframe id", fields[k])))?;
        let height = alt.map(num).transpose()?.unwrap_or(0.0);
        let position = Geodetic::new(num(lat)?, num(lon)?, height).map_err(|e| bad(n + 1, e.to_string()))?;
        let sigma = [num(se)?, num(sn)?];
        if sigma.iter().any(|&s| s < 0.0) {
            return Err(bad(n + 1, format!("negative σ in `{line}`")));
        }
        let truth = match (te, tn) {
            (Some(e), Some(t)) => Some([num(e)?, num(t)?]),
            _ => None,
        };
        out.push(FixRecord {
            keyframe,
            position,
            sigma,
            truth,
        });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_synth_gps_output_and_names_bad_lines() {
        let p = Path::new("fixes.csv");
        let ok = "keyframe,lat,lon,sigma_east,sigma_north,true_east,true_north\n0,45.5,9.2,1.0,2.0,0.0,0.0\n";
        let f = parse_fixes(p, ok).unwrap();
        assert_eq!(
            (f[0].keyframe, f[0].sigma, f[0].truth),
            (0, [1.0, 2.0], Some([0.0, 0.0]))
        );
        let err = parse_fixes(p, "keyframe,lat,lon,sigma_east,sigma_north\n3,95.0,9.2,1,1\n").unwrap_err();
        assert_eq!(
            err.to_string(),
            "fixes.csv:2: GPS fix is out of range (|lat| > 90 or |lon| > 180)"
        );
        let err = parse_fixes(p, "keyframe,lat,lon,sigma_east,sigma_north\n3,45,9.2,-1,1\n").unwrap_err();
        assert_eq!(err.to_string(), "fixes.csv:2: negative σ in `3,45,9.2,-1,1`");
        let err = parse_fixes(p, "keyframe,lat,lon,sigma_north\n").unwrap_err();
        assert_eq!(
            err.to_string(),
            "fixes.csv:1: header lacks the `sigma_east` column"
        );
        let err = parse_fixes(p, "keyframe,lat,lon,sigma_east,sigma_north\n3,45,nan,1,1\n").unwrap_err();
        assert_eq!(err.to_string(), "fixes.csv:2: non-finite number `nan`");
    }
}
