// Exceptions thrown by worker threads reach the caller as themselves: an exception that leaves an
// OpenMP region would otherwise call std::terminate and kill the process (and a Python session).
#include "tprf/core/error.h"
#include "tprf/core/parallel.h"
#include "tprf/geometry/patches.h"
#include "tprf/geometry/visibility.h"
#include "tprf/transport/links.h"

#include "test_scenes.h"

#include <gtest/gtest.h>

#include <atomic>
#include <new>
#include <string>

namespace tprf {
namespace {

TEST(Parallel, EveryIndexRunsOnceWithoutErrors) {
    std::vector<std::atomic<int>> seen(1000);
    parallel_for(seen.size(), {2, 7, true}, [&](std::size_t i) { ++seen[i]; });
    for (std::size_t i = 0; i < seen.size(); ++i) ASSERT_EQ(seen[i].load(), 1) << i;
    std::vector<std::atomic<int>> static_seen(999);
    parallel_for(static_seen.size(), {2, 1, false}, [&](std::size_t i) { ++static_seen[i]; });
    for (std::size_t i = 0; i < static_seen.size(); ++i) ASSERT_EQ(static_seen[i].load(), 1) << i;
}

TEST(Parallel, AWorkersErrorIsRethrownOnTheCallingThreadWithItsMessage) {
    try {
        parallel_for(10000, {2, 1, true}, [&](std::size_t i) {
            if (i == 37) throw Error("bad mesh in worker " + std::to_string(i));
        });
        FAIL() << "no exception reached the caller";
    } catch (const Error& e) {
        EXPECT_EQ(std::string(e.what()), "bad mesh in worker 37");
    }
}

TEST(Parallel, IterationsAfterAFailureAreSkipped) {
    // On one thread the order is fixed: 0..37 run, 37 throws, and nothing after it starts.
    int ran = 0;
    EXPECT_THROW(parallel_for(10000, {1, 1, true},
                              [&](std::size_t i) {
                                  ++ran;
                                  if (i == 37) throw Error("stop");
                              }),
                 Error);
    EXPECT_EQ(ran, 38);
}

TEST(Parallel, AnAllocationFailureInAWorkerKeepsItsType) {
    EXPECT_THROW(parallel_for(64, {2, 1, false},
                              [](std::size_t i) {
                                  if (i == 63) throw std::bad_alloc();
                              }),
                 std::bad_alloc);
}

// A real stage: the link stage reports progress from its worker threads, and a caller cancels by
// throwing from the callback. The cancellation must come back as the tprf::Error it threw.
TEST(Parallel, ACancelledLinkStageThrowsTprfErrorOnTheCaller) {
    Scene scene;
    scene.time = test::time_axis(10, 0.1);
    scene.max_edge = 0.1;
    scene.objects.push_back(test::rectangle({0, 0, 0}, {1, 0, 0}, {0, 1, 0}));
    scene.objects.push_back(test::rectangle({0, 0, 1}, {0, 1, 0}, {1, 0, 0}));
    const PatchSet patches = build_patches(scene);
    ASSERT_EQ(patches.size(), 200u);
    const Visibility visibility(patches);
    LinkOptions options;
    options.threads = 2;
    int calls = 0;
    options.progress = [&](std::string_view phase, double fraction) {
        ++calls;
        if (phase == "links" && fraction < 1.0) throw Error("cancelled at " + std::to_string(fraction));
    };
    EXPECT_THROW(compute_links(patches, visibility, options), Error);
    EXPECT_GE(calls, 1);
}

}  // namespace
}  // namespace tprf
