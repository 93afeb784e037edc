//! The splits: whole groups are held out (leave one group out), and a group's
//! per-group nuisance parameters are cross-fitted on its two halves.

/// The training groups of the fold that holds out group `held_out` of `groups`.
pub fn training_indices(groups: usize, held_out: usize) -> Vec<usize> {
    (0..groups).filter(|&g| g != held_out).collect()
}

/// The calibration masks of two-fold cross-fitting over `samples` samples in their
/// order: the first half, then the second. Nuisance fitted on one mask is scored on
/// the other, so every sample is scored once and never by parameters fitted on it.
pub fn halves(samples: usize) -> [Vec<bool>; 2] {
    let cut = samples / 2;
    let first: Vec<bool> = (0..samples).map(|i| i < cut).collect();
    let second: Vec<bool> = first.iter().map(|b| !b).collect();
    [first, second]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn folds_hold_out_exactly_one_group_and_halves_partition() {
        assert_eq!(training_indices(4, 2), vec![0, 1, 3]);
        let [a, b] = halves(5);
        assert_eq!(a, vec![true, true, false, false, false]);
        assert!(a.iter().zip(&b).all(|(x, y)| x != y));
    }
}
