//! INRIA's view order, seeded.

pub use cocog_formats::rng::SplitMix64;

/// INRIA's `viewpoint_stack`: every epoch visits each view once, in a random order, by popping
/// a random entry of a list refilled when empty.
#[derive(Clone, Debug)]
pub struct ViewOrder {
    views: usize,
    stack: Vec<usize>,
    rng: SplitMix64,
}

impl ViewOrder {
    pub fn new(views: usize, seed: u64) -> Self {
        Self {
            views,
            stack: Vec::new(),
            rng: SplitMix64::new(seed),
        }
    }

    /// Continues an order saved with `state`: the generator and the views left this epoch.
    pub fn resume(views: usize, rng: u64, stack: Vec<usize>) -> Self {
        Self {
            views,
            stack,
            rng: SplitMix64::new(rng),
        }
    }

    /// Generator state and the views not yet visited this epoch.
    pub fn state(&self) -> (u64, &[usize]) {
        (self.rng.state(), &self.stack)
    }

    /// The next view index; `None` only when there are no views.
    pub fn next_view(&mut self) -> Option<usize> {
        if self.views == 0 {
            return None;
        }
        if self.stack.is_empty() {
            self.stack.extend(0..self.views);
        }
        // The modulo bias is below 2⁻⁵⁰ for any realistic view count.
        let i = (self.rng.next_u64() % self.stack.len() as u64) as usize;
        Some(self.stack.remove(i))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn take(order: &mut ViewOrder, n: usize) -> Vec<usize> {
        (0..n).map(|_| order.next_view().unwrap()).collect()
    }

    #[test]
    fn every_epoch_is_a_permutation_and_the_seed_fixes_the_order() {
        let mut a = ViewOrder::new(7, 42);
        let seq = take(&mut a, 21);
        for epoch in seq.chunks(7) {
            let mut sorted = epoch.to_vec();
            sorted.sort_unstable();
            assert_eq!(sorted, (0..7).collect::<Vec<_>>());
        }
        assert_eq!(take(&mut ViewOrder::new(7, 42), 21), seq);
        assert_ne!(take(&mut ViewOrder::new(7, 43), 21), seq);
        assert_eq!(ViewOrder::new(0, 1).next_view(), None);
    }

    #[test]
    fn a_resumed_order_continues_the_same_sequence() {
        let mut a = ViewOrder::new(5, 9);
        take(&mut a, 3);
        let (rng, stack) = a.state();
        let mut b = ViewOrder::resume(5, rng, stack.to_vec());
        assert_eq!(take(&mut b, 12), take(&mut a, 12));
    }
}
