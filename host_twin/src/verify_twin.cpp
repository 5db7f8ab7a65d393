// The host build of kernels/verify_math.cuh: the GPU kernel's arithmetic, run on one thread per pair
// (a team of one), so that a machine without a GPU compares it with the Rust reference.
#include "verify_math.cuh"

extern "C" void clatch_twin_verify_pairs(const clatch_verify_settings* settings, const clatch_verify_pair* pairs,
                                         unsigned int pair_count, const clatch_verify_point* points,
                                         unsigned int* scratch, unsigned int* inliers, clatch_verify_result* results) {
    cv_serial_team team;
    cv_model_buffers buffers;
    for (unsigned int p = 0; p < pair_count; ++p) {
        const clatch_verify_pair& pair = pairs[p];
        unsigned long long first = pair.first;
        unsigned int* lists = scratch + CLATCH_VERIFY_LISTS * first;
        cv_pair_lists l = {lists, lists + pair.count, lists + 2ull * pair.count, lists + 3ull * pair.count};
        cv_estimate_two_view(team, *settings, pair, points + first, l, inliers + first, &buffers, &results[p]);
    }
}
