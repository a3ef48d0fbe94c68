//! iSAM records: `EDGE2|ODOMETRY i j dx dy dθ R11 R12 R13 R22 R23 R33`, where
//! the six numbers are the upper-triangular square root of the information
//! (Ω = RᵀR), not the information itself.

use super::{edge_record, ReadErrorKind, Record};
use crate::graph::Information;

pub(crate) fn parse_line(tokens: &[&str]) -> Result<Record, ReadErrorKind> {
    match tokens[0] {
        "EDGE2" | "ODOMETRY" => edge_record(tokens, tokens[0], Information::from_sqrt_upper),
        tag => Err(ReadErrorKind::Malformed(format!("unknown iSAM record `{tag}`"))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn squares_the_root_information() {
        let tokens: Vec<&str> = "ODOMETRY 3 4 1 0 0 50 0 0 50 0 100".split(' ').collect();
        match parse_line(&tokens).unwrap() {
            Record::Edge(3, 4, _, info) => assert_eq!(info.upper(), [2500.0, 0.0, 0.0, 2500.0, 0.0, 10000.0]),
            r => panic!("unexpected {r:?}"),
        }
    }
}
