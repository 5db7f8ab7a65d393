//! Counter-based sampling: the indices drawn in trial `t` of the pair keyed `p` are a pure function
//! of `(seed, p, stream, t)`, so that any thread of any backend draws any trial's sample on its own,
//! without a generator state carried from trial to trial.
//!
//! Words come from SplitMix64's output function (integer `+ × ^ >>` on `u64`, wrapping); a word
//! becomes an index below `m` by the multiply-high reduction `((w >> 32) · m) >> 32`; a sample of `k`
//! distinct indices below `n` by Floyd's algorithm, which draws exactly `k` words (no rejection loop).

/// One SplitMix64 step: the output for the state `z` (the state advanced by the golden-ratio
/// increment, then mixed), [`crate::synthetic::SplitMix64`]'s first output from seed `z`.
pub(crate) fn splitmix64(z: u64) -> u64 {
    crate::synthetic::SplitMix64::new(z).next_u64()
}

/// Which model a stream of samples feeds (so that E, F, H and the watermark test draw apart).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Stream {
    Essential = 0,
    Fundamental = 1,
    Homography = 2,
    Translation = 3,
}

/// The samples of one estimation: `(seed, pair, stream)` hashed once into a key.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Sampler {
    key: u64,
}

impl Sampler {
    /// `key = splitmix64(splitmix64(splitmix64(seed) ^ pair) ^ stream)`.
    pub(crate) fn new(seed: u64, pair: u64, stream: Stream) -> Self {
        Self {
            key: splitmix64(splitmix64(splitmix64(seed) ^ pair) ^ stream as u64),
        }
    }

    /// Word `j` of trial `t`: `splitmix64(key ^ splitmix64(t · 2^8 + j))` (`j < 2^8`).
    fn word(&self, trial: u64, j: u64) -> u64 {
        splitmix64(self.key ^ splitmix64((trial << 8) | j))
    }

    /// The sample of trial `trial`: `out.len()` distinct indices below `n` (`out.len() ≤ n < 2^32`),
    /// by Floyd's algorithm: for the `j`-th of `m = n − k .. n`, draw `r` below `m + 1`; take `r`
    /// unless already taken, else `m`.
    pub(crate) fn sample(&self, trial: u64, n: u32, out: &mut [u32]) {
        let k = out.len() as u32;
        for (j, m) in (n - k..n).enumerate() {
            let word = self.word(trial, j as u64);
            let r = (((word >> 32) * (u64::from(m) + 1)) >> 32) as u32;
            out[j] = if out[..j].contains(&r) { m } else { r };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn splitmix64_matches_the_reference_sequence() {
        // The first outputs of SplitMix64 seeded with 0 (state advanced by GAMMA each call).
        assert_eq!(splitmix64(0), 0xE220_A839_7B1D_CDAF);
        assert_eq!(splitmix64(0x9E37_79B9_7F4A_7C15), 0x6E78_9E6A_A1B9_65F4);
    }

    #[test]
    fn samples_are_distinct_in_range_and_a_pure_function_of_the_counters() {
        let sampler = Sampler::new(7, 3, Stream::Fundamental);
        let mut seen = vec![0u32; 20];
        for trial in 0..2000 {
            let mut a = [0u32; 7];
            let mut b = [0u32; 7];
            sampler.sample(trial, 20, &mut a);
            Sampler::new(7, 3, Stream::Fundamental).sample(trial, 20, &mut b);
            assert_eq!(a, b);
            let mut sorted = a;
            sorted.sort_unstable();
            assert!(
                sorted.windows(2).all(|w| w[0] < w[1]) && sorted[6] < 20,
                "{a:?}"
            );
            a.iter().for_each(|&i| seen[i as usize] += 1);
        }
        // Every index drawn about 2000 · 7 / 20 = 700 times.
        assert!(seen.iter().all(|&c| (550..850).contains(&c)), "{seen:?}");
        let mut other = [0u32; 7];
        let mut first = [0u32; 7];
        Sampler::new(7, 4, Stream::Fundamental).sample(0, 20, &mut other);
        sampler.sample(0, 20, &mut first);
        assert_ne!(first, other, "another pair draws another sample");
        let mut all = [0u32; 5];
        sampler.sample(0, 5, &mut all);
        all.sort_unstable();
        assert_eq!(all, [0, 1, 2, 3, 4]);
    }
}
