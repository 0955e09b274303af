// The catalogue of (structure, builder, layout) combinations the bench knows:
// every one the three papers and docs/accel.md name, with a flag saying
// whether rayforge implements it yet, so presets can run what exists and
// name what does not.
#pragma once

#include <string>
#include <vector>

#include "rayforge/accel/accel.h"

namespace rf::bench {

struct Candidate {
    std::string structure;  // "bvh", "grid", "kdtree", ...
    std::string builder;    // "binned", "sbvh", ...
    std::string layout;     // how it is traced: "bvh2" = the canonical 32-byte binary nodes
    bool implemented = false;
    // Part of `all`? Brute force is not (far too slow for real scenes): it runs
    // when its structure is named; the +opt variants run when their builder is.
    bool in_all = true;
    std::string Candidate::*named_by = &Candidate::structure;
    BuildOptions options;   // how to build it (implemented ones)
    std::string source;     // paper or seed it comes from

    [[nodiscard]] std::string label() const { return structure + "/" + builder + "/" + layout; }
};

const std::vector<Candidate>& candidate_catalogue();

// Candidates matching every filter; a filter is a list of names or {"all"}.
// Names that match nothing in the catalogue throw rf::Error (typos must not
// silently shrink a benchmark). Unimplemented matches go to `unimplemented`.
std::vector<Candidate> select_candidates(const std::vector<std::string>& structures,
                                         const std::vector<std::string>& builders,
                                         const std::vector<std::string>& layouts,
                                         std::vector<Candidate>* unimplemented);

// Candidates by label ("bvh/binned/bvh2"); unknown labels throw rf::Error.
std::vector<Candidate> candidates_by_label(const std::vector<std::string>& labels, std::vector<Candidate>* unimplemented);

}  // namespace rf::bench
