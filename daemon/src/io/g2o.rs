//! g2o 2-D records: `VERTEX_SE2 id x y θ` and
//! `EDGE_SE2 i j dx dy dθ I11 I12 I13 I22 I23 I33`.

use super::{edge_record, vertex_record, ReadErrorKind, Record};
use crate::graph::Information;

pub(crate) fn parse_line(tokens: &[&str]) -> Result<Record, ReadErrorKind> {
    match tokens[0] {
        "VERTEX_SE2" => vertex_record(tokens, "VERTEX_SE2"),
        "EDGE_SE2" => edge_record(tokens, "EDGE_SE2", Information::from_upper),
        // FIX pins a vertex; slamd always fixes the first keyframe.
        "FIX" => Ok(Record::Skip),
        tag if tag.contains("SE3") || tag.ends_with('3') => Err(ReadErrorKind::Malformed(format!(
            "`{tag}`: a 3-D record in a 2-D graph"
        ))),
        tag => Err(ReadErrorKind::Malformed(format!("unknown g2o record `{tag}`"))),
    }
}
