//! The kernel's verification arithmetic (`kernels/verify_math.cuh`, built as host C++) against the
//! CPU reference (`clatch::verify::verify_pairs`) on generated pairs: every field bit for bit.

use clatch::synthetic::SplitMix64;
use clatch::verify::{VerifyConfig, ViewPair, verify_pairs};

#[path = "../../tests/common/two_view.rs"]
mod two_view;
#[path = "../../tests/common/verify_cases.rs"]
mod verify_cases;

use verify_cases::{Case, case, differences, other_configs};

/// Compares both on `cases` under `config`; panics with the first difference.
fn compare(cases: &[Case], config: &VerifyConfig) -> usize {
    let pairs: Vec<ViewPair<'_>> = cases.iter().map(Case::pair).collect();
    let want = verify_pairs(&pairs, config).expect("valid pairs");
    let got = clatch_host_twin::verify_pairs(&pairs, config);
    let mut differing = 0;
    let mut first = None;
    for ((c, w), g) in cases.iter().zip(&want).zip(&got) {
        let (count, what) = differences(w, g);
        differing += count;
        if first.is_none() {
            first = what.map(|what| format!("{}: {what}", c.name));
        }
    }
    assert_eq!(
        differing,
        0,
        "{differing} fields differ; first: {}",
        first.unwrap_or_default()
    );
    cases.len()
}

#[test]
fn every_generated_pair_is_bit_identical_to_the_cpu_reference() {
    let cases: Vec<Case> = (0..1530).map(|i| case(1, i)).collect();
    let compared = compare(&cases, &VerifyConfig::default());
    println!("compared {compared} pairs, 0 differences");
}

#[test]
fn other_settings_are_bit_identical_too() {
    let cases: Vec<Case> = (0..300).map(|i| case(2, i)).collect();
    let configs = other_configs();
    for config in &configs {
        compare(&cases, config);
    }
    println!(
        "compared {} pairs under {} settings, 0 differences",
        cases.len(),
        configs.len()
    );
}

#[test]
fn the_warps_division_of_the_work_is_bit_identical_too() {
    // Small pairs (32 threads a pair, every collective a barrier), every shape and oddity.
    let cases: Vec<Case> = (0..400)
        .map(|i| case(3, i))
        .filter(|c| c.matches.len() <= 40)
        .step_by(3)
        .collect();
    let config = VerifyConfig::default().with_max_num_trials(150);
    let pairs: Vec<ViewPair<'_>> = cases.iter().map(Case::pair).collect();
    let want = verify_pairs(&pairs, &config).expect("valid pairs");
    let got = clatch_host_twin::verify_pairs_on_warp(&pairs, &config);
    let mut differing = 0;
    for ((c, w), g) in cases.iter().zip(&want).zip(&got) {
        let (count, what) = differences(w, g);
        differing += count;
        assert_eq!(count, 0, "{}: {}", c.name, what.unwrap_or_default());
    }
    println!(
        "compared {} pairs on a 32-thread team, {differing} differences",
        cases.len()
    );
}
