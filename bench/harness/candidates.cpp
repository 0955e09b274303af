#include "candidates.h"

#include <algorithm>
#include <set>
#include <tuple>
#include <utility>

#include "rayforge/core/error.h"

namespace rf::bench {
namespace {

// What rayforge implements so far: a candidate runs when every part of it is
// here. Flip entries on as structures land.
bool builder_implemented(const std::string& builder) {
    static const std::set<std::string> names = {"binned",  "sweep",   "sbvh",          "lbvh30", "lbvh63",
                                                "hlbvh2",  "gridbvh", "gridbvh-split", "ploc",   "hploc", "+opt",
                                                "+treelets"};
    return names.count(builder) != 0;
}
bool layout_implemented(const std::string& layout) {
    static const std::set<std::string> names = {"bvh2", "bvh4", "bvh8"};
    return names.count(layout) != 0;
}
bool structure_implemented(const std::string& structure) {
    static const std::set<std::string> names = {"bvh", "brute", "kdtree", "grid", "grid-proximity"};
    return names.count(structure) != 0;
}

Candidate make(std::string structure, std::string builder, std::string layout, std::string source,
               const BuildOptions& options) {
    Candidate c;
    c.structure = std::move(structure);
    c.builder = std::move(builder);
    c.layout = std::move(layout);
    c.source = std::move(source);
    c.options = options;
    return c;
}

std::vector<Candidate> make_catalogue() {
    std::vector<Candidate> all;
    struct BuilderInfo {
        const char* name;
        Builder builder;
        const char* source;
    };
    const BuilderInfo builders[] = {
        {"binned", Builder::BinnedSah, "Wald 2007, binned SAH"},
        {"sweep", Builder::SweepSah, "full sweep SAH"},
        {"sbvh", Builder::Sbvh, "Stich et al. 2009, spatial splits"},
        {"lbvh30", Builder::Lbvh30, "Karras 2012, 30-bit Morton codes"},
        {"lbvh63", Builder::Lbvh63, "Karras 2012, 63-bit Morton codes"},
        {"hlbvh2", Builder::Hlbvh2, "Garanzha 2014, ch. 5 (HLBVH2)"},
        {"gridbvh", Builder::GridBvh, "Garanzha 2014, ch. 4 (GridBvh)"},
        {"gridbvh-split", Builder::GridBvhSplit, "Garanzha 2014, ch. 4 (GridBvhSplit, partial triangles)"},
        {"ploc", Builder::Ploc, "Meister and Bittner 2018"},
        {"hploc", Builder::Hploc, "Benthin et al. 2024 (H-PLOC)"},
    };
    const std::pair<const char*, Layout> layouts[] = {
        {"bvh2", Layout::Bvh2}, {"bvh4", Layout::Bvh4}, {"bvh8", Layout::Bvh8}};
    for (const auto& [layout_name, layout] : layouts) {
        for (const BuilderInfo& info : builders) {
            // The builder alone, then with each post-build optimizer.
            for (const std::string optimizer : {"", "+opt", "+treelets"}) {
                const bool optimize = !optimizer.empty();
                BuildOptions options;
                options.structure = Structure::Bvh;
                options.builder = info.builder;
                options.layout = layout;
                options.reinsertion.enabled = optimizer == "+opt";
                options.treelets.enabled = optimizer == "+treelets";
                const char* then = optimizer == "+opt" ? ", then reinsertion" : optimize ? ", then treelet restructuring" : "";
                Candidate c = make("bvh", std::string(info.name) + optimizer, layout_name, std::string(info.source) + then,
                                   options);
                c.implemented = builder_implemented(info.name) && layout_implemented(layout_name) &&
                                (!optimize || builder_implemented(optimizer));
                // Optimised variants run only when named (they double a bench's length).
                c.in_all = !optimize;
                c.named_by = &Candidate::builder;
                all.push_back(c);
            }
        }
    }

    BuildOptions brute_options;
    brute_options.structure = Structure::BruteForce;
    Candidate brute = make("brute", "none", "triangles", "reference: every triangle", brute_options);
    brute.implemented = true;
    brute.in_all = false;
    all.push_back(brute);

    for (const auto& [res_name, res] : {std::pair{"32", 32}, {"64", 64}, {"128", 128}, {"auto", 0}}) {
        for (const auto& [structure_name, structure, source] :
             {std::tuple{"grid", Structure::Grid, "Bogolepov et al., Zlatuška 2009, 3D-DDA"},
              {"grid-proximity", Structure::ProximityGrid, "Bogolepov et al., proximity clouds"}}) {
            BuildOptions options;
            options.structure = structure;
            options.grid.resolution = res;
            Candidate c = make(structure_name, std::string("uniform-") + res_name, "grid", source, options);
            c.implemented = structure_implemented(structure_name);
            all.push_back(c);
        }
    }
    for (const auto& [traversal_name, traversal] :
         {std::pair{"stack", KdTraversal::Stack}, {"short-stack", KdTraversal::ShortStack},
          {"restart", KdTraversal::Restart}, {"pushdown", KdTraversal::Pushdown}}) {
        BuildOptions options;
        options.structure = Structure::KdTree;
        options.kdtree.traversal = traversal;
        Candidate c = make("kdtree", "sah", traversal_name, "Zlatuška 2009, Wald and Havran 2006", options);
        c.implemented = structure_implemented("kdtree");
        all.push_back(c);
    }
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
        // Candidates left out of `all` run only when named explicitly.
        if (!c.in_all && !named(c.named_by == &Candidate::builder ? builders : structures, c.*c.named_by)) continue;
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
