// The host build of kernels/verify_math.cuh: the GPU kernel's arithmetic, run on the host so that a
// machine without a GPU compares it with the Rust reference. Two teams: one thread per pair (the
// arithmetic), and 32 threads per pair standing in for the kernel's warp (the warp's collectives:
// ballots, ranks, sums, synchronisation, the lanes' split of the trials), which deadlocks or differs
// where the kernel's lanes would disagree.
#include "verify_math.cuh"

#include <condition_variable>
#include <mutex>
#include <thread>
#include <vector>

namespace {

cv_pair_lists lists_of(unsigned int* scratch, const clatch_verify_pair& pair) {
    unsigned int* lists = scratch + CLATCH_VERIFY_LISTS * pair.first;
    cv_pair_lists l = {lists, lists + pair.count, lists + 2ull * pair.count, lists + 3ull * pair.count};
    return l;
}

// A reusable barrier for the 32 lanes of one team.
class Barrier {
  public:
    explicit Barrier(int n) : n_(n) {}
    void wait() {
        std::unique_lock<std::mutex> lock(mutex_);
        unsigned long long generation = generation_;
        if (++waiting_ == n_) {
            waiting_ = 0;
            ++generation_;
            cv_.notify_all();
        } else {
            cv_.wait(lock, [&] { return generation != generation_; });
        }
    }

  private:
    std::mutex mutex_;
    std::condition_variable cv_;
    int n_;
    int waiting_ = 0;
    unsigned long long generation_ = 0;
};

struct LaneShared {
    Barrier barrier{32};
    unsigned long long values[32];
};

// The warp of kernels/verify.cu, as 32 threads: every collective is a barrier, a write of each
// lane's value, a barrier, a read of all 32 and a barrier, as __ballot_sync and __shfl_xor_sync give
// every lane the same answer.
struct ThreadTeam {
    enum { SIZE = 32 };
    LaneShared* shared;
    unsigned int lane_id;
    unsigned int lane() const { return lane_id; }
    bool leader() const { return lane_id == 0; }
    void sync() const { shared->barrier.wait(); }
    unsigned long long gather(unsigned long long x, unsigned int below) const {
        sync();
        shared->values[lane_id] = x;
        sync();
        unsigned long long total = 0;
        for (unsigned int i = 0; i < below; ++i) total += shared->values[i];
        sync();
        return total;
    }
    unsigned int count(bool flag) const { return (unsigned int)gather(flag ? 1 : 0, 32); }
    unsigned int rank(bool flag) const { return (unsigned int)gather(flag ? 1 : 0, lane_id); }
    unsigned long long sum(unsigned long long x) const { return gather(x, 32); }
};

}  // namespace

extern "C" void clatch_twin_verify_pairs(const clatch_verify_settings* settings, const clatch_verify_pair* pairs,
                                         unsigned int pair_count, const clatch_verify_point* points,
                                         unsigned int* scratch, unsigned int* inliers, clatch_verify_result* results) {
    cv_serial_team team;
    cv_model_buffers buffers;
    for (unsigned int p = 0; p < pair_count; ++p) {
        const clatch_verify_pair& pair = pairs[p];
        cv_estimate_two_view(team, *settings, pair, points + pair.first, lists_of(scratch, pair), inliers + pair.first,
                             &buffers, &results[p]);
    }
}

extern "C" void clatch_twin_verify_pairs_warp(const clatch_verify_settings* settings, const clatch_verify_pair* pairs,
                                              unsigned int pair_count, const clatch_verify_point* points,
                                              unsigned int* scratch, unsigned int* inliers,
                                              clatch_verify_result* results) {
    for (unsigned int p = 0; p < pair_count; ++p) {
        const clatch_verify_pair& pair = pairs[p];
        LaneShared shared;
        cv_model_buffers buffers;
        std::vector<std::thread> lanes;
        for (unsigned int lane = 0; lane < 32; ++lane)
            lanes.emplace_back([&, lane] {
                ThreadTeam team = {&shared, lane};
                cv_estimate_two_view(team, *settings, pair, points + pair.first, lists_of(scratch, pair),
                                     inliers + pair.first, &buffers, &results[p]);
            });
        for (std::thread& t : lanes) t.join();
    }
}
