//! Byte offsets of a document → 1-based line and column, as roxmltree counts them (lines by
//! `\n`, columns in characters). roxmltree's own `text_pos_at` scans the text from its start
//! at every call, so giving each node a location cost time quadratic in the document; here the
//! line starts are indexed once and the column is counted on from the last position asked for
//! when the walk moves forward on the same line, which a walk in document order does.

use std::cell::Cell;

/// The position index of one document.
pub(super) struct Positions<'t> {
    text: &'t str,
    /// Byte offset of the start of every line.
    line_starts: Vec<usize>,
    /// The last position asked for: (offset, line index, column).
    last: Cell<(usize, usize, u32)>,
}

impl<'t> Positions<'t> {
    pub(super) fn new(text: &'t str) -> Self {
        let mut line_starts = vec![0];
        line_starts.extend(text.bytes().enumerate().filter(|(_, b)| *b == b'\n').map(|(i, _)| i + 1));
        Positions { text, line_starts, last: Cell::new((0, 0, 1)) }
    }

    /// Line and column of byte `offset` (clamped to the text).
    pub(super) fn at(&self, offset: usize) -> (u32, u32) {
        let mut offset = offset.min(self.text.len());
        while !self.text.is_char_boundary(offset) {
            offset -= 1;
        }
        let line = self.line_starts.partition_point(|&s| s <= offset) - 1;
        let (last_offset, last_line, last_column) = self.last.get();
        let column = if last_line == line && last_offset <= offset {
            last_column + self.text[last_offset..offset].chars().count() as u32
        } else {
            1 + self.text[self.line_starts[line]..offset].chars().count() as u32
        };
        self.last.set((offset, line, column));
        (line as u32 + 1, column)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn positions_agree_with_roxmltree_in_any_order() {
        let text = "<a>\n  <bé x=\"1\"/><c/>\r\n<d>\n\n</d></a>";
        let doc = roxmltree::Document::parse(text).unwrap();
        let positions = Positions::new(text);
        let mut offsets: Vec<usize> = doc.descendants().map(|n| n.range().start).collect();
        offsets.extend([0, text.len()]);
        for pass in 0..2 {
            for &o in &offsets {
                let p = doc.text_pos_at(o);
                assert_eq!(positions.at(o), (p.row, p.col), "offset {o}, pass {pass}");
            }
            offsets.reverse();
        }
    }
}
