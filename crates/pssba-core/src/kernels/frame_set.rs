//! A set of frame indices as a bitset, for per-kernel scratch work: inserting is O(1) and the
//! frames come back in ascending order without a sort (a kernel of a 1000-frame window touches
//! hundreds of frames; the bitset is 16 words).

/// Frames `0..capacity` as bits, kept empty between uses.
#[derive(Debug, Default, Clone)]
pub struct FrameSet {
    words: Vec<u64>,
}

impl FrameSet {
    /// Room for frames `0..frames` (grows only).
    pub fn reserve_frames(&mut self, frames: usize) {
        let words = frames.div_ceil(64);
        if self.words.len() < words {
            self.words.resize(words, 0);
        }
    }

    /// Adds `frame` (below the reserved count); true if it was not in the set.
    #[inline]
    pub fn insert(&mut self, frame: usize) -> bool {
        let (word, bit) = (frame / 64, 1u64 << (frame % 64));
        let new = self.words[word] & bit == 0;
        self.words[word] |= bit;
        new
    }

    /// Calls `f` on every frame of the set in ascending order and empties the set.
    pub fn drain_ascending(&mut self, mut f: impl FnMut(usize)) {
        for (w, word) in self.words.iter_mut().enumerate() {
            let mut bits = std::mem::take(word);
            while bits != 0 {
                f(w * 64 + bits.trailing_zeros() as usize);
                bits &= bits - 1;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_come_back_sorted_once_and_the_set_empties() {
        let mut set = FrameSet::default();
        set.reserve_frames(1000);
        let frames = [999, 0, 64, 63, 500, 64, 1, 999, 128];
        let new: Vec<bool> = frames.iter().map(|&f| set.insert(f)).collect();
        assert_eq!(
            new,
            [true, true, true, true, true, false, true, false, true]
        );
        let mut out = Vec::new();
        set.drain_ascending(|f| out.push(f));
        assert_eq!(out, vec![0, 1, 63, 64, 128, 500, 999]);
        let mut again = Vec::new();
        set.drain_ascending(|f| again.push(f));
        assert!(again.is_empty());
        assert!(set.insert(5));
    }
}
