//! Cutting a list of pairs into blocks of bounded device memory, and the records one block's launch
//! reads (`clatch_pair`, `clatch_pair_task` of `kernels/clatch.h`).

use std::ops::Range;

use crate::cuda::header::{CLATCH_PAIRS_BLOCK_QUERIES, clatch_pair, clatch_pair_task};

const BLOCK_QUERIES: usize = CLATCH_PAIRS_BLOCK_QUERIES as usize;

/// Where one pair's sets lie: rows of the query buffer and of the gallery buffer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct PairRows {
    pub(crate) query_row: usize,
    pub(crate) query_rows: usize,
    pub(crate) train_row: usize,
    pub(crate) train_rows: usize,
}

/// Most work one block holds on the device at once: query rows (one best-match and one kept record
/// each), gallery rows (one reverse key each) and pairs. A single pair larger than the budget is a
/// block of its own.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Budget {
    pub(crate) query_rows: usize,
    pub(crate) train_rows: usize,
    pub(crate) pairs: usize,
}

impl Budget {
    /// About 70 MB of device scratch and 24 MB of pinned host memory per block in flight: 419 pairs of
    /// 5000 x 5000 (10.5 G descriptor pairs, tens of milliseconds of kernel time) per block.
    pub(crate) const DEFAULT: Budget = Budget {
        query_rows: 1 << 21,
        train_rows: 1 << 21,
        pairs: 1 << 16,
    };
}

/// A run of consecutive input pairs matched by one launch.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct Block {
    /// The input pairs it covers, in order.
    pub(crate) range: Range<usize>,
    /// The pairs of `range` matched on the device, with their input index; the others (no query, or
    /// too small a gallery) have no matches.
    pub(crate) device: Vec<(usize, PairRows)>,
    pub(crate) query_rows: usize,
    pub(crate) train_rows: usize,
    /// Query blocks of `CLATCH_PAIRS_BLOCK_QUERIES` over all of `device`: one kernel block each.
    pub(crate) tasks: usize,
}

impl Block {
    fn starting_at(start: usize) -> Self {
        Self {
            range: start..start,
            device: Vec::new(),
            query_rows: 0,
            train_rows: 0,
            tasks: 0,
        }
    }

    fn fits(&self, rows: &PairRows, budget: Budget) -> bool {
        self.device.is_empty()
            || (self.query_rows + rows.query_rows <= budget.query_rows
                && self.train_rows + rows.train_rows <= budget.train_rows
                && self.device.len() < budget.pairs)
    }

    fn push(&mut self, index: usize, rows: Option<PairRows>) {
        self.range.end = index + 1;
        if let Some(rows) = rows {
            self.query_rows += rows.query_rows;
            self.train_rows += rows.train_rows;
            self.tasks += rows.query_rows.div_ceil(BLOCK_QUERIES);
            self.device.push((index, rows));
        }
    }

    /// The launch's pair records (each pair's records and reverse keys packed one after the other)
    /// and its task list (every query block of every pair, in pair order).
    pub(crate) fn layout(&self) -> (Vec<clatch_pair>, Vec<clatch_pair_task>) {
        let mut pairs = Vec::with_capacity(self.device.len());
        let mut tasks = Vec::with_capacity(self.tasks);
        let (mut best_row, mut reverse_row) = (0usize, 0usize);
        for (p, (_, rows)) in self.device.iter().enumerate() {
            pairs.push(clatch_pair {
                query_row: rows.query_row as u64,
                train_row: rows.train_row as u64,
                best_row: best_row as u64,
                reverse_row: reverse_row as u64,
                query_rows: rows.query_rows as u32,
                train_rows: rows.train_rows as u32,
            });
            for query_block in 0..rows.query_rows.div_ceil(BLOCK_QUERIES) {
                tasks.push(clatch_pair_task {
                    pair: p as u32,
                    query_block: query_block as u32,
                });
            }
            best_row += rows.query_rows;
            reverse_row += rows.train_rows;
        }
        (pairs, tasks)
    }
}

/// Cuts `places` (one per input pair; `None` for a pair without device work) into consecutive blocks
/// within `budget`, covering every input pair once, in order.
pub(crate) fn blocks(places: &[Option<PairRows>], budget: Budget) -> Vec<Block> {
    let mut out = Vec::new();
    let mut block = Block::starting_at(0);
    for (index, place) in places.iter().enumerate() {
        if let Some(rows) = place
            && !block.fits(rows, budget)
        {
            let next = Block::starting_at(index);
            out.push(std::mem::replace(&mut block, next));
        }
        block.push(index, *place);
    }
    if !block.range.is_empty() {
        out.push(block);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rows(query_rows: usize, train_rows: usize) -> Option<PairRows> {
        Some(PairRows {
            query_row: 16,
            query_rows,
            train_row: 32,
            train_rows,
        })
    }

    #[test]
    fn blocks_cover_every_pair_once_in_order_within_the_budget() {
        let budget = Budget {
            query_rows: 1000,
            train_rows: 700,
            pairs: 3,
        };
        let places = [
            rows(300, 300),
            None,
            rows(300, 300),
            rows(500, 10),
            None,
            rows(2000, 5000), // larger than the budget: a block of its own
            rows(1, 1),
            rows(1, 1),
            rows(1, 1),
            rows(1, 1),
            None,
        ];
        let blocks = blocks(&places, budget);
        let mut next = 0;
        for block in &blocks {
            assert_eq!(block.range.start, next);
            next = block.range.end;
            assert!(!block.device.is_empty() || block.range.len() == 1);
            if block.device.len() > 1 {
                assert!(block.query_rows <= budget.query_rows);
                assert!(block.train_rows <= budget.train_rows);
                assert!(block.device.len() <= budget.pairs);
            }
            for &(i, r) in &block.device {
                assert!(block.range.contains(&i));
                assert_eq!(places[i], Some(r));
            }
        }
        assert_eq!(next, places.len());
        let ranges: Vec<_> = blocks.iter().map(|b| b.range.clone()).collect();
        assert_eq!(ranges, vec![0..3, 3..5, 5..6, 6..9, 9..11]);
    }

    #[test]
    fn layout_packs_records_and_lists_every_query_block() {
        let blocks = blocks(
            &[rows(257, 3), None, rows(256, 2), rows(1, 9)],
            Budget::DEFAULT,
        );
        assert_eq!(blocks.len(), 1);
        let (pairs, tasks) = blocks[0].layout();
        assert_eq!(pairs.len(), 3);
        assert_eq!(
            pairs
                .iter()
                .map(|p| (p.best_row, p.reverse_row))
                .collect::<Vec<_>>(),
            vec![(0, 0), (257, 3), (513, 5)]
        );
        assert_eq!(tasks.len(), blocks[0].tasks);
        assert_eq!(
            tasks
                .iter()
                .map(|t| (t.pair, t.query_block))
                .collect::<Vec<_>>(),
            vec![(0, 0), (0, 1), (1, 0), (2, 0)]
        );
        assert!(
            super::blocks(&[None, None], Budget::DEFAULT)[0]
                .device
                .is_empty()
        );
        assert!(super::blocks(&[], Budget::DEFAULT).is_empty());
    }
}
