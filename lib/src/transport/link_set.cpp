#include "tprf/transport/link_set.h"

#include "patch_pairs.h"
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
                      double bin_width_m, const LinkOptions& options, LinkSetStats counts) {
    HierarchyStats* stats = counts.hierarchy;
    LinkStats* flat_stats = counts.flat;
    const int rings = patches.glossy_rings_for(settings.glossy_resolution);
    const bool glossy = rings > 0 && bin_width_m > 0.0;
    LinkSet set;
    if (settings.method == LinkMethod::Flat) {
        set = flat_link_set(patches, visibility, options, flat_stats);
    } else {
        HierarchyOptions hierarchy;
        hierarchy.tolerance = settings.tolerance;
        hierarchy.bin_width_m = bin_width_m;
        hierarchy.time_bins = settings.time_bins;
        set = hierarchical_link_set(patches, visibility, options, hierarchy, stats);
    }
    if (settings.spread_pieces > 0 && bin_width_m > 0.0)
        spread_patch_links(set, patches, bin_width_m, settings.spread_pieces, options.threads);
    if (glossy) add_glossy_links(set, patches, visibility, options, bin_width_m, rings);
    return set;
}

LinkBuildSizes link_build_sizes(const HierarchyOptions& options) {
    LinkBuildSizes s;
    s.flat_pair = flat_pair_bytes();
    s.hierarchical_pair = hierarchical_pair_bytes();
    s.oracle_node = oracle_node_bytes(options);
    s.spread_link = sizeof(RowLink);
    s.mirror_link = mirror_link_bytes();
    return s;
}

}  // namespace tprf
