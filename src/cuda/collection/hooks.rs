//! Test and bench hooks of `cuda/collection/` (the `internals` feature only): not part of the API.

use super::*;

/// A device collection of `sets` (one width) matched over `pairs` in blocks of at most `pairs_per_block`
/// pairs and `rows_per_block` query and gallery rows: lets the tests reach many blocks, both slots and
/// blocks without device work with small sets; on kernel family `kernel` (the device's choice when
/// `None`). Results in pair order.
pub fn match_pairs_in_blocks(
    dev: Arc<GpuDevice>,
    sets: &[&DescriptorSet],
    pairs: &[(usize, usize)],
    config: &MatchConfig,
    (pairs_per_block, rows_per_block): (usize, usize),
    kernel: Option<MatchKernel>,
) -> Result<Vec<Vec<Match>>> {
    let collection = filled(dev, sets)?;
    let mut out = Vec::with_capacity(pairs.len());
    collection.match_pairs_within(
        pairs,
        config,
        (budget(pairs_per_block, rows_per_block), kernel),
        &mut |_, m| out.push(m),
    )?;
    Ok(out)
}

/// [`match_pairs_in_blocks`] for `query` against every set of `sets`, through the collection's search.
pub fn search_in_blocks(
    dev: Arc<GpuDevice>,
    sets: &[&DescriptorSet],
    query: &DescriptorSet,
    config: &MatchConfig,
    (pairs_per_block, rows_per_block): (usize, usize),
    kernel: Option<MatchKernel>,
) -> Result<Vec<Vec<Match>>> {
    let collection = filled(dev, sets)?;
    let ids: Vec<usize> = (0..sets.len()).collect();
    let mut out = Vec::with_capacity(ids.len());
    collection.search_within(
        query,
        &ids,
        config,
        (budget(pairs_per_block, rows_per_block), kernel),
        &mut |_, m| out.push(m),
    )?;
    Ok(out)
}

fn budget(pairs: usize, rows: usize) -> Budget {
    Budget {
        query_rows: rows,
        train_rows: rows,
        pairs: pairs.max(1),
    }
}

/// A collection holding `sets`, added one at a time so that the buffer grows several times.
fn filled(dev: Arc<GpuDevice>, sets: &[&DescriptorSet]) -> Result<DeviceCollection> {
    let width = sets.first().map_or(DescriptorWidth::FULL, |s| s.width());
    let mut collection = DeviceCollection::new(dev, width)?;
    for set in sets {
        collection.add(&[set])?;
    }
    Ok(collection)
}

/// A device collection holding `sets` (added one at a time), kept so that tests can match it many
/// times, from several threads at once and from inside its own callbacks, on a chosen kernel family.
#[derive(Debug)]
pub struct HeldCollection(DeviceCollection);

impl HeldCollection {
    /// A collection of `sets` (one width) on `dev`.
    pub fn new(dev: Arc<GpuDevice>, sets: &[&DescriptorSet]) -> Result<Self> {
        filled(dev, sets).map(Self)
    }

    /// [`DeviceCollection::match_pairs`] in blocks of at most `pairs_per_block` pairs and
    /// `rows_per_block` rows (as [`match_pairs_in_blocks`]), on kernel family `kernel` (the device's
    /// choice when `None`); `each(p, matches)` as blocks complete.
    pub fn match_pairs(
        &self,
        pairs: &[(usize, usize)],
        config: &MatchConfig,
        (pairs_per_block, rows_per_block): (usize, usize),
        kernel: Option<MatchKernel>,
        each: &mut dyn FnMut(usize, Vec<Match>),
    ) -> Result<()> {
        let budget = budget(pairs_per_block, rows_per_block);
        self.0
            .match_pairs_within(pairs, config, (budget, kernel), each)
    }

    /// [`DeviceCollection::search`] of `query` against every held set, blocks and family as
    /// [`HeldCollection::match_pairs`].
    pub fn search(
        &self,
        query: &DescriptorSet,
        config: &MatchConfig,
        (pairs_per_block, rows_per_block): (usize, usize),
        kernel: Option<MatchKernel>,
        each: &mut dyn FnMut(usize, Vec<Match>),
    ) -> Result<()> {
        let ids: Vec<usize> = (0..self.0.places.len()).collect();
        let budget = budget(pairs_per_block, rows_per_block);
        self.0
            .search_within(query, &ids, config, (budget, kernel), each)
    }
}

/// Set `id` of a CUDA `collection`, read back from the device (blocking): lets the tests compare what
/// [`crate::DescriptorCollection::add_pending`] put there with the host's features bit for bit.
/// [`Error::InvalidInput`] for a CPU collection, an error past the last set.
pub fn read_set(collection: &crate::DescriptorCollection, id: usize) -> Result<DescriptorSet> {
    let held = collection
        .device_store()
        .ok_or_else(|| Error::InvalidInput {
            what: "collection",
            reason: "only a CUDA collection holds sets on the device; this one is on the cpu"
                .into(),
        })?;
    let place = held.place(id)?;
    let words = held.width.words();
    let rows = held
        .stream
        .clone_dtoh(
            &held
                .rows
                .slice(place.first_row * words..(place.first_row + place.rows) * words),
        )
        .map_err(driver_error("reading a collection's set back"))?;
    DescriptorSet::from_words(held.width, rows)
}
