// Links through mirrors and glass: the diffuse transfer from patch j to patch i along a chain of
// specular reflections is the transfer from j's mirror image (geometry/mirror_images.h), seen through
// the chain's polygons. Each is an ordinary link of the link set (a weight and a delay), so the solver
// marches them as any other.

#include "tprf/transport/link_set.h"

#include "tprf/core/error.h"
#include "tprf/core/parallel.h"
#include "tprf/geometry/form_factors.h"
#include "tprf/geometry/mirror_images.h"
#include "tprf/geometry/patches.h"
#include "tprf/geometry/visibility.h"
#include "tprf/transport/glossy_rows.h"
#include "patch_pairs.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <numeric>
#include <tuple>

namespace tprf {
namespace {

using Extra = ExtraLink;

bool on_side(const SpecularPlane& s, int side, const Vec3* poly, std::size_t count) {
    for (std::size_t k = 0; k < count; ++k)
        if (side * s.normal.dot(poly[k] - s.point) > 0.0) return true;
    return false;
}

// The chain's planes as seen from the receiver: plane j's polygons through R1 ... R(j-1).
struct UnfoldedChain {
    std::vector<std::vector<std::vector<Vec3>>> windows;  // [plane][polygon] corners
};

UnfoldedChain unfold_windows(const MirrorChain& chain, const std::vector<SpecularPlane>& planes) {
    UnfoldedChain u;
    Unfolding frame;
    for (int j = 0; j < chain.length; ++j) {
        const SpecularPlane& s = planes[chain.plane[std::size_t(j)]];
        std::vector<std::vector<Vec3>> polys;
        for (std::size_t k = 0; k < s.polygons(); ++k) {
            std::vector<Vec3> poly;
            for (std::uint32_t c = s.first[k]; c < s.first[k + 1]; ++c) poly.push_back(frame(s.corners[c]));
            polys.push_back(std::move(poly));
        }
        u.windows.push_back(std::move(polys));
        frame = frame.after(Unfolding::reflection(s.point, s.normal));
    }
    return u;
}

// Form factor from the point x (normal n) to the convex polygon `poly` (normal `normal`), any corner count.
double fan_form_factor(const Vec3& x, const Vec3& n, const std::vector<Vec3>& poly, const Vec3& normal) {
    if (poly.size() <= 8) return point_polygon_form_factor(x, n, poly.data(), poly.size(), normal);
    double f = 0.0;
    for (std::size_t k = 1; k + 1 < poly.size(); ++k) {
        const Vec3 tri[3] = {poly[0], poly[k], poly[k + 1]};
        f += point_polygon_form_factor(x, n, tri, 3, normal);
    }
    return f;
}

// Form factor from x to the part of the image polygon seen through every window of the chain, from
// level `level` on.
double through_windows(const Vec3& x, const Vec3& n, const std::vector<Vec3>& poly, const Vec3& normal,
                       const UnfoldedChain& u, std::size_t level) {
    if (poly.empty()) return 0.0;
    if (level == u.windows.size()) return fan_form_factor(x, n, poly, normal);
    double f = 0.0;
    for (const std::vector<Vec3>& w : u.windows[level]) {
        const Vec3 wn = (w[1] - w[0]).cross(w[2] - w[0]);
        const bool front = wn.dot(x - w[0]) > 0.0;
        f += through_windows(x, n, clip_to_window(poly, x, w.data(), w.size(), front), normal, u, level + 1);
    }
    return f;
}

struct ChainPair {
    const PatchSet& patches;
    const Visibility& vis;
    const MirrorChain& chain;
    const UnfoldedChain& windows;
    const std::vector<double>& radius;
};

// The share of rays between stratified points of i and of j's image that pass (mirrors' reflectance
// and glass included), among those whose path exists; 1 when no sampled path exists.
double chain_visibility(const ChainPair& c, std::size_t i, std::size_t j, const LinkOptions& options) {
    const double lift = c.vis.epsilon();
    const int total = std::clamp(options.visibility_rays, 1, 16), first = std::clamp(options.first_rays, 1, total);
    const int g = 4;
    double passed = 0.0;
    int through = 0;
    for (int k = 0; k < total; ++k) {
        if (k == first && through > 0 && (passed == 0.0 || passed == through * c.chain.reflectance)) break;
        const double ui = (k % g + hash01(i, j, 4 * std::uint64_t(k))) / g;
        const double vi = (k / g + hash01(i, j, 4 * std::uint64_t(k) + 1)) / g;
        const int kj = (k * 5 + 3) % 16;
        const double uj = (kj % g + hash01(i, j, 4 * std::uint64_t(k) + 2)) / g;
        const double vj = (kj / g + hash01(i, j, 4 * std::uint64_t(k) + 3)) / g;
        const Vec3 x = patch_point(c.patches, i, ui, vi) + lift * c.patches.normal[i];
        const Vec3 y = patch_point(c.patches, j, uj, vj) + lift * c.patches.normal[j];
        bool exists = false;
        const double w = c.vis.unfolded(c.chain, x, c.chain.image(y), &exists);
        if (!exists) continue;
        ++through;
        passed += w;
    }
    return through > 0 ? passed / through : c.chain.reflectance;
}

// F_ij along the chain, visibility and the specular weights included; 0 when nothing passes.
double chain_form_factor(const ChainPair& c, std::size_t i, std::size_t j, const LinkOptions& options,
                         float& distance) {
    const PatchSet& p = c.patches;
    std::vector<Vec3> image;
    for (std::size_t k = p.corners(j); k-- > 0;) image.push_back(c.chain.image(p.polygon(j)[k]));
    const Vec3 image_normal = c.chain.unfold.linear * p.normal[j];
    const Vec3 image_centroid = c.chain.image(p.centroid[j]);
    bool receiver_front = false, source_front = false;
    for (std::size_t k = 0; k < p.corners(i); ++k) receiver_front |= image_normal.dot(p.polygon(i)[k] - image_centroid) > 0.0;
    for (const Vec3& y : image) source_front |= p.normal[i].dot(y - p.centroid[i]) > 0.0;
    if (!receiver_front || !source_front) return 0.0;
    const double d = (p.centroid[i] - image_centroid).norm();
    const double r = c.radius[i] + c.radius[j];
    const int q = d < options.near_factor * r ? 4 : d < options.far_factor * r ? 2 : 1;
    double f = 0.0;
    for (int s = 0; s < q * q; ++s) {
        const Vec3 x = patch_point(p, i, (s % q + 0.5) / q, (s / q + 0.5) / q);
        f += through_windows(x, p.normal[i], image, image_normal, c.windows, 0);
    }
    f /= double(q * q);
    if (!(f > 0.0)) return 0.0;
    distance = float(d);
    return f * chain_visibility(c, i, j, options);
}

// A patch's polygon through the chain's unfolding (`forward`: as the receiving end sees the sending
// end; else its inverse, as the sending end sees the receiving end), with its normal and centroid.
struct ImagePolygon {
    std::vector<Vec3> corners;
    Vec3 normal, centroid;
};

ImagePolygon image_of(const PatchSet& p, std::size_t j, const MirrorChain& chain, bool forward) {
    const auto map = [&](const Vec3& x) { return forward ? chain.unfold(x) : chain.unfold.inverse(x); };
    ImagePolygon out;
    for (std::size_t k = p.corners(j); k-- > 0;) out.corners.push_back(map(p.polygon(j)[k]));
    out.normal = forward ? Vec3(chain.unfold.linear * p.normal[j]) : Vec3(chain.unfold.linear.transpose() * p.normal[j]);
    out.centroid = map(p.centroid[j]);
    return out;
}

// A chain's pair (i receiving, j sending along the chain) with a glossy end: its cells' links, from
// each glossy end's side (glossy_pair_cells): the chain's direction and its reverse, one and the same
// for a patch that sees itself through a palindrome.
void glossy_chain_links(const ChainPair& c, const GlossyRows& rows, const GlossyPair& base, bool palindrome,
                        double near_factor, std::vector<Extra>& out) {
    const PatchSet& p = c.patches;
    const std::size_t i = base.i, j = base.j;
    const ImagePolygon from_i = image_of(p, j, c.chain, true), from_j = image_of(p, i, c.chain, false);
    const bool near = (p.centroid[i] - from_i.centroid).norm() < near_factor * (c.radius[i] + c.radius[j]);
    const auto shares = [&](std::size_t at, const ImagePolygon& other, std::size_t other_patch) {
        return cell_shares(p, rows.rings, at,
                           {other.corners.data(), other.corners.size(), other.normal, other.centroid,
                            c.radius[other_patch], near});
    };
    GlossyPair pair = base;
    if (rows.slot[j] >= 0) pair.at_j = shares(j, from_j, i);
    if (rows.slot[i] >= 0) {
        pair.at_i = shares(i, from_i, j);
        glossy_pair_cells(rows, pair, out);
    }
    if (rows.slot[j] < 0 || (i == j && palindrome)) return;
    GlossyPair back = pair;  // the same pair from j's side
    std::swap(back.i, back.j);
    std::swap(back.f_ij, back.f_ji);
    std::swap(back.i_sends, back.j_sends);
    std::swap(back.at_i, back.at_j);
    glossy_pair_cells(rows, back, out);
}

// The links along one chain (and, by reciprocity, along its reverse), each with the chain's tint; with
// glossy rows, a glossy end's cells too (glossy_chain_links).
void chain_links(const PairScene& scene, const MirrorChain& chain, bool palindrome, std::uint16_t tint,
                 const GlossyRows& glossy, std::vector<std::vector<Extra>>& rows) {
    const PatchSet& patches = scene.patches;
    const Visibility& vis = scene.vis;
    const LinkOptions& options = scene.options;
    const std::vector<double>& radius = scene.radius;
    const std::vector<SpecularPlane>& planes = vis.planes();
    const SpecularPlane& first = planes[chain.plane[0]];
    const SpecularPlane& last = planes[chain.plane[std::size_t(chain.length - 1)]];
    std::vector<std::uint32_t> receivers, sources;
    const auto is_glossy = [&](std::size_t i) { return !glossy.empty() && glossy.slot[i] >= 0; };
    for (std::uint32_t i = 0; i < patches.size(); ++i) {
        if (inert(patches, i) && !is_glossy(i)) continue;
        if (on_side(first, chain.side[0], patches.polygon(i), patches.corners(i))) receivers.push_back(i);
        if (on_side(last, chain.side[std::size_t(chain.length - 1)], patches.polygon(i), patches.corners(i)))
            sources.push_back(i);
    }
    const UnfoldedChain windows = unfold_windows(chain, planes);
    const ChainPair pair{patches, vis, chain, windows, radius};
    parallel_for(receivers.size(), {options.threads, 4, true}, [&](std::size_t k) {
        const std::uint32_t i = receivers[k];
        std::vector<Extra>& out = rows[k];
        for (const std::uint32_t j : sources) {
            if (palindrome && j < i) continue;
            float distance = 0.0f;
            const double f = chain_form_factor(pair, i, j, options, distance);
            if (!(f > 0.0)) continue;
            const double f_ji = f * patches.area[i] / patches.area[j];
            const bool i_sends = !inert(patches, i), j_sends = !inert(patches, j);
            if (i_sends && j_sends) {
                out.push_back({i, j, float(f), distance, tint});
                if (i != j || !palindrome) out.push_back({j, i, float(f_ji), distance, tint});
            }
            if (is_glossy(i) || is_glossy(j)) {
                GlossyPair g;
                g.i = i;
                g.j = j;
                g.f_ij = f;
                g.f_ji = f_ji;
                g.distance = distance;
                g.tint = tint;
                g.i_sends = i_sends;
                g.j_sends = j_sends;
                glossy_chain_links(pair, glossy, g, palindrome, options.near_factor, out);
            }
        }
    });
}

bool lexicographically_first(const MirrorChain& a, const MirrorChain& b) {
    for (int k = 0; k < a.length; ++k) {
        const auto ka = std::pair(a.plane[std::size_t(k)], a.side[std::size_t(k)]);
        const auto kb = std::pair(b.plane[std::size_t(k)], b.side[std::size_t(k)]);
        if (ka != kb) return ka < kb;
    }
    return true;  // equal: a palindrome
}

bool same(const MirrorChain& a, const MirrorChain& b) {
    for (int k = 0; k < a.length; ++k)
        if (a.plane[std::size_t(k)] != b.plane[std::size_t(k)] || a.side[std::size_t(k)] != b.side[std::size_t(k)])
            return false;
    return true;
}

}  // namespace

std::uint64_t add_mirror_links(LinkSet& set, const PatchSet& patches, const Visibility& vis,
                               const LinkOptions& options, double bin_width_m) {
    const std::vector<MirrorChain>& chains = vis.chains();
    if (chains.empty()) return 0;
    const std::vector<double> radius = circumradii(patches);
    std::vector<Extra> extra;
    std::vector<std::array<float, 3>>& tints = set.links.tints;
    for (const MirrorChain& chain : chains) {
        const MirrorChain back = reversed(chain, vis.planes());
        if (!lexicographically_first(chain, back)) continue;  // its reverse carries both directions
        std::uint16_t tint = 0;  // a tinted chain's links carry its tint (the reverse's is the same product)
        if (!(chain.tint == 1.0).all()) {
            if (tints.empty()) tints.push_back({1.0f, 1.0f, 1.0f});
            if (tints.size() > 0xffff) throw Error("more than 65535 tinted chains of mirrors; lower solver.max_specular");
            tints.push_back({float(chain.tint[0]), float(chain.tint[1]), float(chain.tint[2])});
            tint = std::uint16_t(tints.size() - 1);
        }
        std::vector<std::vector<Extra>> rows(patches.size());
        chain_links({patches, vis, options, radius}, chain, same(chain, back), tint, set.glossy, rows);
        for (auto& r : rows) extra.insert(extra.end(), r.begin(), r.end());
    }
    const std::uint64_t added = extra.size();
    merge_extra_links(set, extra, bin_width_m);
    return added;
}

void merge_extra_links(LinkSet& set, std::vector<Extra>& extra, double bin_width_m) {
    Links& l = set.links;
    const std::size_t nodes = l.receivers();
    const bool by_octave = set.tree.nodes() > set.tree.leaves && bin_width_m > 0.0;
    const float inv_bin = by_octave ? float(1.0 / bin_width_m) : 0.0f;
    std::sort(extra.begin(), extra.end(), [](const Extra& a, const Extra& b) { return a.receiver < b.receiver; });
    Links out;
    out.row.assign(nodes + 1, 0);
    out.source.reserve(l.size() + extra.size());
    out.ff.reserve(l.size() + extra.size());
    out.distance.reserve(l.size() + extra.size());
    const bool tinted = l.tinted() || std::any_of(extra.begin(), extra.end(), [](const Extra& x) { return x.tint != 0; });
    if (tinted) out.tints = l.tints;
    std::size_t e = 0;
    std::vector<Extra> row;
    for (std::size_t r = 0; r < nodes; ++r) {
        row.clear();
        for (std::uint64_t k = l.row[r]; k < l.row[r + 1]; ++k)
            row.push_back({std::uint32_t(r), l.source[k], l.ff[k], l.distance[k], l.tint.empty() ? std::uint16_t(0) : l.tint[k]});
        for (; e < extra.size() && extra[e].receiver == r; ++e) row.push_back(extra[e]);
        const auto key = [&](const Extra& a) {
            return std::tuple(by_octave ? delay_octave(a.distance, inv_bin) : 0, a.source, a.distance);
        };
        std::stable_sort(row.begin(), row.end(), [&](const Extra& a, const Extra& b) { return key(a) < key(b); });
        for (const Extra& x : row) {
            out.source.push_back(x.source);
            out.ff.push_back(x.ff);
            out.distance.push_back(x.distance);
            if (tinted) out.tint.push_back(x.tint);
        }
        out.row[r + 1] = out.source.size();
    }
    l = std::move(out);
}

std::size_t mirror_link_bytes() { return sizeof(Extra) + Links::kLinkBytes; }

}  // namespace tprf
