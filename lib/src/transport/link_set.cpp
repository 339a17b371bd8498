#include "tprf/transport/link_set.h"

#include "tprf/geometry/patches.h"

namespace tprf {

LinkSet flat_link_set(const PatchSet& patches, const Visibility& visibility, const LinkOptions& options,
                      LinkStats* stats) {
    LinkSet set;
    set.tree = leaves_only(patches);
    set.links = compute_links(patches, visibility, options, stats);
    return set;
}

LinkSet make_link_set(const PatchSet& patches, const Visibility& visibility, const LinkSettings& settings,
                      double bin_width_m, const LinkOptions& options, HierarchyStats* stats) {
    if (settings.method == LinkMethod::Flat) return flat_link_set(patches, visibility, options);
    HierarchyOptions hierarchy;
    hierarchy.tolerance = settings.tolerance;
    hierarchy.bin_width_m = bin_width_m;
    hierarchy.time_bins = settings.time_bins;
    return hierarchical_link_set(patches, visibility, options, hierarchy, stats);
}

}  // namespace tprf
