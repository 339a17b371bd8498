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
    LinkSet set;
    if (settings.method == LinkMethod::Flat) {
        set = flat_link_set(patches, visibility, options);
    } else {
        HierarchyOptions hierarchy;
        hierarchy.tolerance = settings.tolerance;
        hierarchy.bin_width_m = bin_width_m;
        hierarchy.time_bins = settings.time_bins;
        set = hierarchical_link_set(patches, visibility, options, hierarchy, stats);
    }
    add_mirror_links(set, patches, visibility, options, bin_width_m);
    return set;
}

}  // namespace tprf
