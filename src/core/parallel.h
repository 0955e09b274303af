// The few parallel patterns rayforge uses (for, invoke, reduce), on TBB.
//
// Every parallel call goes through here for one reason: Debian's libtbb is not
// built for ThreadSanitizer, so TSan cannot see the happens-before edges of
// TBB's fork and join and would report every task's result as a race. Under
// TSan (scripts/run-sanitizers.sh thread) these wrappers announce the edges:
// the caller releases before forking and each task acquires it; each task
// releases when done and the caller acquires after the join. Tasks never
// synchronise with their siblings, so races between them are still reported.
// In normal builds the annotations compile to nothing.
#pragma once

#include <cstddef>
#include <utility>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>
#include <tbb/parallel_reduce.h>
#include <tbb/task_arena.h>

#if defined(__SANITIZE_THREAD__)
#include <sanitizer/tsan_interface.h>
#define RF_TSAN_RELEASE(addr) __tsan_release(const_cast<void*>(static_cast<const void*>(addr)))
#define RF_TSAN_ACQUIRE(addr) __tsan_acquire(const_cast<void*>(static_cast<const void*>(addr)))
#else
#define RF_TSAN_RELEASE(addr) ((void)(addr))
#define RF_TSAN_ACQUIRE(addr) ((void)(addr))
#endif

namespace rf::parallel {

// Synchronisation objects for one fork/join: only their addresses matter.
struct ForkJoin {
    char fork = 0;
    char join = 0;
    ForkJoin() { RF_TSAN_RELEASE(&fork); }
    void task_begins() const { RF_TSAN_ACQUIRE(&fork); }
    void task_ends() const { RF_TSAN_RELEASE(&join); }
    void joined() const { RF_TSAN_ACQUIRE(&join); }
};

// body(lo, hi) over [begin, end) in chunks of about `grain`.
template <class Index, class Body>
void for_range(Index begin, Index end, Index grain, Body&& body) {
    ForkJoin sync;
    tbb::parallel_for(tbb::blocked_range<Index>(begin, end, grain), [&](const tbb::blocked_range<Index>& r) {
        sync.task_begins();
        body(r.begin(), r.end());
        sync.task_ends();
    });
    sync.joined();
}

// body(i) for every i in [begin, end).
template <class Index, class Body>
void for_each_index(Index begin, Index end, Body&& body) {
    for_range(begin, end, Index(1), [&](Index lo, Index hi) {
        for (Index i = lo; i < hi; ++i) body(i);
    });
}

// Runs both functions, possibly at once, and returns when both are done.
template <class F, class G>
void invoke(F&& f, G&& g) {
    ForkJoin sync;
    tbb::parallel_invoke(
        [&] {
            sync.task_begins();
            f();
            sync.task_ends();
        },
        [&] {
            sync.task_begins();
            g();
            sync.task_ends();
        });
    sync.joined();
}

// Reduction over [begin, end): body(lo, hi, acc) -> acc folds a chunk into a
// partial result; combine(a, b) -> a merges two partial results.
template <class Index, class Value, class Body, class Combine>
Value reduce(Index begin, Index end, Index grain, Value identity, Body&& body, Combine&& combine) {
    ForkJoin sync;
    Value result = tbb::parallel_reduce(
        tbb::blocked_range<Index>(begin, end, grain), std::move(identity),
        [&](const tbb::blocked_range<Index>& r, Value acc) {
            sync.task_begins();
            acc = body(r.begin(), r.end(), std::move(acc));
            sync.task_ends();
            return acc;
        },
        [&](Value a, const Value& b) {
            // Joins read partial results other tasks wrote.
            RF_TSAN_ACQUIRE(&sync.join);
            a = combine(std::move(a), b);
            sync.task_ends();
            return a;
        });
    sync.joined();
    return result;
}

// Runs f with at most `threads` worker threads (0 = all cores).
template <class F>
auto with_threads(int threads, F&& f) {
    if (threads <= 0) return f();
    tbb::task_arena arena(threads);
    return arena.execute(std::forward<F>(f));
}

}  // namespace rf::parallel
