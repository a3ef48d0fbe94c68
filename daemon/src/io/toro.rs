//! TORO 2-D records: `VERTEX2 id x y θ` and
//! `EDGE2 i j dx dy dθ Ixx Ixy Iyy Iθθ Ixθ Iyθ` (note the information order).

use super::{edge_record, vertex_record, ReadErrorKind, Record};
use crate::graph::Information;

pub(crate) fn parse_line(tokens: &[&str]) -> Result<Record, ReadErrorKind> {
    match tokens[0] {
        "VERTEX2" | "VERTEX" => vertex_record(tokens, tokens[0]),
        "EDGE2" | "EDGE" => edge_record(tokens, tokens[0], Information::from_toro),
        tag => Err(ReadErrorKind::Malformed(format!("unknown TORO record `{tag}`"))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_toro_information_order() {
        let tokens: Vec<&str> = "EDGE2 0 1 1 0 0 10 1 20 30 2 3".split(' ').collect();
        match parse_line(&tokens).unwrap() {
            Record::Edge(0, 1, _, info) => assert_eq!(info.upper(), [10.0, 1.0, 2.0, 20.0, 3.0, 30.0]),
            r => panic!("unexpected {r:?}"),
        }
    }
}
