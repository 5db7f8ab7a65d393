//! Canary for a compiler bug met while writing tests/rotation.rs: rustc 1.95.0 (59807616e 2026-04-14)
//! miscompiles this safe code at opt-level 1 and above (the test profile uses 2): the second call of the
//! closure returns a mix of values from different calls. It comes from the MIR optimisations:
//! disabling the `GVN` or the `DeadStoreElimination-final` MIR pass makes it correct, as does
//! opt-level 0; rustc 1.97.0-nightly (2026-05-19) compiles it correctly.
//!
//! Nothing in clatch is known to be affected (the golden and hand-recomputed bits pass), but a bit-exact
//! reference implementation should not be built with a compiler that gets this wrong.

#[inline(never)]
fn rotate(mut p: [i64; 2], one: i64, height: usize, turns: usize) -> [i64; 2] {
    for _ in 0..turns {
        p = [one * (height as i64 - 1) - p[1], p[0]];
    }
    p
}

#[test]
#[ignore = "rustc 1.95.0 miscompiles this (MIR GVN + DeadStoreElimination); run it to check a toolchain"]
fn closure_returning_an_array_called_twice() {
    let (one, height, turns) = std::hint::black_box((65536i64, 512usize, 1usize));
    let u: [i64; 2] = std::hint::black_box([16076, 3161]);
    let v: [i64; 2] = std::hint::black_box([-3161, 16076]);
    let turned = |vector: [i64; 2]| {
        let (origin, end) = (
            rotate([0, 0], one, height, turns),
            rotate(vector, one, height, turns),
        );
        [end[0] - origin[0], end[1] - origin[1]]
    };
    let both = turned(u) == [-3161, 16076] && turned(v) == [-16076, -3161];
    assert!(both);
    assert_eq!(turned(u), [-3161, 16076]);
}
