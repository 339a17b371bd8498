#include "tprf/transport/link_set.h"

#include "tprf/geometry/patches.h"

namespace tprf {

Links emitter_links(const PatchSet& patches, const Links& links) {
    const std::size_t n = patches.size();
    Links out;
    out.row.assign(n + 1, 0);
    for (std::size_t i = 0; i < n; ++i) {
        for (std::uint64_t k = links.row[i]; k < links.row[i + 1]; ++k) {
            const std::uint32_t j = links.source[k];
            if (j >= n || !(patches.emission[j] > 0.0).any()) continue;
            out.source.push_back(j);
            out.ff.push_back(links.ff[k]);
            out.distance.push_back(links.distance[k]);
        }
        out.row[i + 1] = out.source.size();
    }
    return out;
}

LinkSet flat_link_set(const PatchSet& patches, const Visibility& visibility, const LinkOptions& options,
                      LinkStats* stats) {
    LinkSet set;
    set.tree = leaves_only(patches);
    set.links = compute_links(patches, visibility, options, stats);
    set.emitters = emitter_links(patches, set.links);
    return set;
}

LinkSet make_link_set(const PatchSet& patches, const Visibility& visibility, const LinkSettings& settings,
                      double bin_width_m, const LinkOptions& options, HierarchyStats* stats) {
    if (settings.method == LinkMethod::Flat) return flat_link_set(patches, visibility, options);
    HierarchyOptions hierarchy;
    hierarchy.tolerance = settings.tolerance;
    hierarchy.bin_width_m = bin_width_m;
    return hierarchical_link_set(patches, visibility, options, hierarchy, stats);
}

}  // namespace tprf
