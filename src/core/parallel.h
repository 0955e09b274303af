// The few parallel patterns rayforge uses (for, invoke, reduce), on TBB.
//
// Every parallel call goes through here so that ThreadSanitizer can check our
// code: Debian's libtbb is not built for TSan, which then cannot see the
// happens-before edges of TBB's fork and join (inside the library) and reports
// every task's result as a race. A TSan build (scripts/run-sanitizers.sh
// thread) therefore runs the same patterns on std::thread, whose creation and
// join TSan understands; races between our tasks are still reported.
#pragma once

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <thread>
#include <utility>
#include <vector>

#if !defined(__SANITIZE_THREAD__)
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>
#include <tbb/parallel_reduce.h>
#include <tbb/task_arena.h>
#endif

namespace rf::parallel {

#if !defined(__SANITIZE_THREAD__)

// body(lo, hi) over [begin, end) in chunks of about `grain`.
template <class Index, class Body>
void for_range(Index begin, Index end, Index grain, Body&& body) {
    tbb::parallel_for(tbb::blocked_range<Index>(begin, end, grain),
                      [&](const tbb::blocked_range<Index>& r) { body(r.begin(), r.end()); });
}

// Runs both functions, possibly at once, and returns when both are done.
template <class F, class G>
void invoke(F&& f, G&& g) {
    tbb::parallel_invoke(std::forward<F>(f), std::forward<G>(g));
}

// Reduction over [begin, end): body(lo, hi, acc) -> acc folds a chunk into a
// partial result; combine(a, b) -> a merges two partial results.
template <class Index, class Value, class Body, class Combine>
Value reduce(Index begin, Index end, Index grain, Value identity, Body&& body, Combine&& combine) {
    return tbb::parallel_reduce(
        tbb::blocked_range<Index>(begin, end, grain), std::move(identity),
        [&](const tbb::blocked_range<Index>& r, Value acc) { return body(r.begin(), r.end(), std::move(acc)); },
        [&](Value a, const Value& b) { return combine(std::move(a), b); });
}

// Runs f with at most `threads` worker threads (0 = all cores).
template <class F>
auto with_threads(int threads, F&& f) {
    if (threads <= 0) return f();
    tbb::task_arena arena(threads);
    return arena.execute(std::forward<F>(f));
}

#else  // ThreadSanitizer build: plain threads.

namespace detail {
// Bounds the threads alive at once when invoke() recurses.
inline std::atomic<int> live_threads{0};
inline constexpr int kMaxLiveThreads = 16;
inline int worker_count() { return std::max(2, int(std::thread::hardware_concurrency())); }
}  // namespace detail

template <class Index, class Body>
void for_range(Index begin, Index end, Index grain, Body&& body) {
    if (end <= begin) return;
    grain = std::max<Index>(grain, Index(1));
    const size_t chunks = (size_t(end - begin) + size_t(grain) - 1) / size_t(grain);
    const size_t workers = std::min<size_t>(chunks, size_t(detail::worker_count()));
    std::vector<std::thread> threads;
    for (size_t w = 0; w < workers; ++w) {
        threads.emplace_back([&, w] {
            for (size_t c = w; c < chunks; c += workers) {
                const Index lo = Index(begin + Index(c) * grain);
                body(lo, std::min<Index>(end, Index(lo + grain)));
            }
        });
    }
    for (std::thread& t : threads) t.join();
}

template <class F, class G>
void invoke(F&& f, G&& g) {
    if (detail::live_threads.fetch_add(1) >= detail::kMaxLiveThreads) {
        detail::live_threads.fetch_sub(1);
        f();
        g();
        return;
    }
    std::thread other([&] { g(); });
    f();
    other.join();
    detail::live_threads.fetch_sub(1);
}

template <class Index, class Value, class Body, class Combine>
Value reduce(Index begin, Index end, Index grain, Value identity, Body&& body, Combine&& combine) {
    if (end <= begin) return identity;
    grain = std::max<Index>(grain, Index(1));
    const size_t chunks = (size_t(end - begin) + size_t(grain) - 1) / size_t(grain);
    // One slot per chunk, wrapped so that vector<bool> cannot pack
    // neighbouring chunks' results into one word written by two threads.
    struct Slot {
        Value value;
    };
    std::vector<Slot> partial(chunks, Slot{identity});
    for_range(size_t(0), chunks, size_t(1), [&](size_t lo, size_t hi) {
        for (size_t c = lo; c < hi; ++c) {
            const Index chunk_begin = Index(begin + Index(c) * grain);
            partial[c].value = body(chunk_begin, std::min<Index>(end, Index(chunk_begin + grain)), partial[c].value);
        }
    });
    Value result = std::move(identity);
    for (const Slot& s : partial) result = combine(std::move(result), s.value);
    return result;
}

template <class F>
auto with_threads(int /*threads*/, F&& f) {
    return f();
}

#endif

// body(i) for every i in [begin, end).
template <class Index, class Body>
void for_each_index(Index begin, Index end, Body&& body) {
    for_range(begin, end, Index(1), [&](Index lo, Index hi) {
        for (Index i = lo; i < hi; ++i) body(i);
    });
}

namespace detail {
template <class T, class Less>
void merge_sort(T* data, T* tmp, size_t n, const Less& less) {
    constexpr size_t kSerialSize = 32 * 1024;
    if (n <= kSerialSize) {
        std::sort(data, data + n, less);
        return;
    }
    const size_t half = n / 2;
    invoke([&] { merge_sort(data, tmp, half, less); }, [&] { merge_sort(data + half, tmp + half, n - half, less); });
    std::merge(data, data + half, data + half, data + n, tmp, less);
    std::copy(tmp, tmp + n, data);
}
}  // namespace detail

// Sorts `values` by `less` (not stable): halves sorted in parallel, then merged.
template <class T, class Less>
void sort(std::vector<T>& values, const Less& less) {
    std::vector<T> tmp(values.size());
    detail::merge_sort(values.data(), tmp.data(), values.size(), less);
}

}  // namespace rf::parallel
