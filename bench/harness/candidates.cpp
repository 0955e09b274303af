#include "candidates.h"

#include <algorithm>
#include <set>

#include "rayforge/core/error.h"

namespace rf::bench {
namespace {

Candidate planned(std::string structure, std::string builder, std::string layout, std::string source) {
    Candidate c;
    c.structure = std::move(structure);
    c.builder = std::move(builder);
    c.layout = std::move(layout);
    c.source = std::move(source);
    return c;
}

std::vector<Candidate> make_catalogue() {
    std::vector<Candidate> all;
    Candidate binned = planned("bvh", "binned", "bvh2", "Wald 2007, binned SAH");
    binned.implemented = true;
    binned.options.structure = Structure::Bvh;
    binned.options.builder = Builder::BinnedSah;
    all.push_back(binned);

    Candidate brute = planned("brute", "none", "triangles", "reference: every triangle");
    brute.implemented = true;
    brute.in_all = false;
    brute.options.structure = Structure::BruteForce;
    all.push_back(brute);

    // Planned (issue 4); flip `implemented` and fill `options` as each lands.
    all.push_back(planned("bvh", "sweep", "bvh2", "full sweep SAH"));
    all.push_back(planned("bvh", "sbvh", "bvh2", "Stich et al. 2009, spatial splits"));
    all.push_back(planned("bvh", "lbvh30", "bvh2", "Karras 2012, 30-bit Morton codes"));
    all.push_back(planned("bvh", "lbvh63", "bvh2", "Karras 2012, 63-bit Morton codes"));
    all.push_back(planned("bvh", "hlbvh2", "bvh2", "seed 000 ch. 5 (HLBVH2)"));
    all.push_back(planned("bvh", "gridbvh", "bvh2", "seed 000 ch. 4 (GridBvh)"));
    all.push_back(planned("bvh", "gridbvh-split", "bvh2", "seed 000 ch. 4 (GridBvhSplit, partial triangles)"));
    all.push_back(planned("bvh", "ploc", "bvh2", "Meister and Bittner 2018"));
    for (const char* res : {"32", "64", "128", "auto"}) {
        all.push_back(planned("grid", std::string("uniform-") + res, "grid", "seeds 001/002, 3D-DDA"));
        all.push_back(planned("proximity-grid", std::string("uniform-") + res, "grid", "seed 001, proximity clouds"));
    }
    for (const char* traversal : {"stack", "short-stack", "restart", "pushdown"})
        all.push_back(planned("kdtree", "sah", traversal, "seed 002, Wald and Havran 2006"));
    return all;
}

bool matches(const std::vector<std::string>& filter, const std::string& value) {
    return std::find(filter.begin(), filter.end(), "all") != filter.end() ||
           std::find(filter.begin(), filter.end(), value) != filter.end();
}

void check_known(const std::vector<std::string>& filter, const char* what,
                 std::string Candidate::*field) {
    std::set<std::string> known;
    for (const Candidate& c : candidate_catalogue()) known.insert(c.*field);
    for (const std::string& name : filter) {
        if (name == "all" || known.count(name)) continue;
        std::string list;
        for (const std::string& k : known) list += (list.empty() ? "" : ", ") + k;
        throw Error(std::string("unknown ") + what + " '" + name + "' (known: " + list + ", all)");
    }
}

}  // namespace

const std::vector<Candidate>& candidate_catalogue() {
    static const std::vector<Candidate> catalogue = make_catalogue();
    return catalogue;
}

std::vector<Candidate> select_candidates(const std::vector<std::string>& structures,
                                         const std::vector<std::string>& builders,
                                         const std::vector<std::string>& layouts,
                                         std::vector<Candidate>* unimplemented) {
    check_known(structures, "structure", &Candidate::structure);
    check_known(builders, "builder", &Candidate::builder);
    check_known(layouts, "layout", &Candidate::layout);
    const auto named = [](const std::vector<std::string>& filter, const std::string& value) {
        return std::find(filter.begin(), filter.end(), value) != filter.end();
    };
    std::vector<Candidate> chosen;
    for (const Candidate& c : candidate_catalogue()) {
        if (!matches(structures, c.structure) || !matches(builders, c.builder) || !matches(layouts, c.layout))
            continue;
        // Structures left out of `all` run only when named explicitly.
        if (!c.in_all && !named(structures, c.structure)) continue;
        if (c.implemented) chosen.push_back(c);
        else if (unimplemented) unimplemented->push_back(c);
    }
    return chosen;
}

std::vector<Candidate> candidates_by_label(const std::vector<std::string>& labels,
                                           std::vector<Candidate>* unimplemented) {
    std::vector<Candidate> chosen;
    for (const std::string& label : labels) {
        const auto& catalogue = candidate_catalogue();
        const auto it = std::find_if(catalogue.begin(), catalogue.end(),
                                     [&](const Candidate& c) { return c.label() == label; });
        if (it == catalogue.end()) throw Error("unknown candidate '" + label + "'");
        if (it->implemented) chosen.push_back(*it);
        else if (unimplemented) unimplemented->push_back(*it);
    }
    return chosen;
}

}  // namespace rf::bench
