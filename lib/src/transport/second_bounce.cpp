#include "tprf/transport/second_bounce.h"

#include "tprf/core/error.h"
#include "tprf/core/parallel.h"
#include "tprf/geometry/patches.h"
#include "tprf/transport/illumination.h"
#include "tprf/transport/link_set.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace tprf {

SecondBounceLight::SecondBounceLight(const PatchSet& patches, const LinkSet& links, const Illumination& illumination,
                               const TimeAxis& time, const SecondBounceOptions& options)
    : m_patches(patches), m_links(links), m_time(time), m_delay(options.delay), m_threads(options.threads) {
    const int max_bounces = options.max_bounces, threads = options.threads;
    const std::size_t n = patches.size();
    TPRF_CHECK_EQ(links.patches(), n);
    TPRF_CHECK_EQ(illumination.row.size(), n + 1);
    const Senders senders = take_pulses(illumination, max_bounces);
    m_lo.assign(n, 0);
    m_hi.assign(n, 0);
    m_gradient.assign(n, {0, 0, 0});
    m_hessian.assign(n, {0, 0, 0, 0, 0, 0});
    std::vector<char> any(n, 0);
    parallel_for(n, {threads, 64, true}, [&](std::size_t i) { any[i] = plan_receiver(i, senders); });
    m_any = std::any_of(any.begin(), any.end(), [](char a) { return a != 0; });
}

SecondBounceLight::Senders SecondBounceLight::take_pulses(const Illumination& illumination, int max_bounces) {
    const std::size_t n = m_patches.size();
    const BinMap bins = m_time.bin_map();
    Senders s;
    s.weight.assign(n, 0.0);
    s.first.assign(n, std::numeric_limits<std::int64_t>::max());
    s.last.assign(n, std::numeric_limits<std::int64_t>::min());
    m_row.assign(n + 1, 0);
    std::vector<std::pair<std::int64_t, const Pulse*>> pulses;  // of one sender, by order then bin
    for (std::size_t j = 0; j < n; ++j) {
        pulses.clear();
        for (std::uint64_t k = illumination.row[j]; k < illumination.row[j + 1]; ++k) {
            const Pulse& p = illumination.pulses[k];
            if (!p.propagates || !(p.energy > 0.0).any()) continue;
            if (max_bounces >= 0 && p.order + 1 > max_bounces) continue;
            const std::int64_t bin = bins.bin(p.path);  // as SolvePlan::pulse_bin
            pulses.push_back({bin, &p});
            s.weight[j] += p.energy.mean();
            s.first[j] = std::min(s.first[j], bin);
            s.last[j] = std::max(s.last[j], bin);
        }
        std::sort(pulses.begin(), pulses.end(), [](const auto& a, const auto& b) {
            return std::pair(a.second->order, a.first) < std::pair(b.second->order, b.first);
        });
        for (std::size_t a = 0; a < pulses.size();) {  // one run per order, over its bins
            std::size_t b = a;
            while (b < pulses.size() && pulses[b].second->order == pulses[a].second->order) ++b;
            const std::int64_t lo = pulses[a].first, length = pulses[b - 1].first - lo + 1;
            m_runs.push_back({lo, std::uint32_t(length), m_energy.size(), pulses[a].second->order});
            m_energy.resize(m_energy.size() + std::size_t(length) * 3, 0.0f);
            float* e = m_energy.data() + m_runs.back().offset;
            for (; a < b; ++a)
                for (int c = 0; c < 3; ++c)
                    e[std::size_t(pulses[a].first - lo) * 3 + std::size_t(c)] += float(pulses[a].second->energy[c]);
        }
        m_row[j + 1] = m_runs.size();
    }
    return s;
}

bool SecondBounceLight::plan_receiver(std::size_t i, const Senders& senders) {
    const Links& l = m_links.links;
    const float inv_bin_f = m_time.inv_bin_f();
    std::int64_t lo = std::numeric_limits<std::int64_t>::max(), hi = std::numeric_limits<std::int64_t>::min();
    Vec3 d = Vec3::Zero();
    Eigen::Matrix3d h = Eigen::Matrix3d::Zero();
    double total = 0.0;
    for (std::uint64_t k = l.row[i]; k < l.row[i + 1]; ++k) {
        const std::uint32_t j = l.source[k];
        if (j >= m_patches.size() || m_row[j] == m_row[j + 1]) continue;  // a cluster, or sends nothing
        const int lag = delay_taps_f(l.distance[k], inv_bin_f, m_delay, 1.0f).lag;
        lo = std::min(lo, senders.first[j] + lag);
        hi = std::max(hi, senders.last[j] + lag + 2);
        const double c = double(l.ff[k]) * senders.weight[j];  // the light this link brings
        const Vec3 offset = m_patches.centroid[i] - m_patches.centroid[j];
        const double r = offset.norm();
        if (!(c > 0.0) || !(r > 0.0)) continue;
        const Vec3 u = offset / r;
        d += c * u;
        h += (c / r) * (Eigen::Matrix3d::Identity() - u * u.transpose());
        total += c;
    }
    if (lo >= hi) return false;
    m_lo[i] = lo;
    m_hi[i] = hi;
    if (total > 0.0) {
        d /= total;
        h /= total;
        m_gradient[i] = {float(d.x()), float(d.y()), float(d.z())};
        m_hessian[i] = {float(h(0, 0)), float(h(1, 1)), float(h(2, 2)), float(h(0, 1)), float(h(0, 2)), float(h(1, 2))};
    }
    return true;
}

void SecondBounceLight::fill(BinSpan span, const std::function<bool(int)>& takes, float* rows, std::size_t stride,
                          std::vector<char>& lit, const std::vector<char>* wanted) const {
    const std::int64_t first_bin = span.first;
    const std::size_t bins = span.count;
    const std::size_t n = m_patches.size();
    const std::int64_t end = first_bin + std::int64_t(bins);
    lit.assign(n, 0);
    // The orders the caller takes, once (pulse orders are below 256).
    bool taken[256];
    for (int o = 0; o < 256; ++o) taken[o] = takes(o + 1);
    const Links& l = m_links.links;
    const float inv_bin_f = m_time.inv_bin_f();
    parallel_for(n, {m_threads, 64, true}, [&](std::size_t i) {
        float* row = rows + i * stride;
        std::fill_n(row, bins * 3, 0.0f);
        if (m_hi[i] <= first_bin || m_lo[i] >= end || (wanted && !(*wanted)[i])) return;
        bool touched = false;
        // Sums in the row first (the solver's G), then times the albedo.
        for (std::uint64_t k = l.row[i]; k < l.row[i + 1]; ++k) {
            const std::uint32_t j = l.source[k];
            if (j >= n || m_row[j] == m_row[j + 1]) continue;  // a cluster, or sends nothing
            const DelayTaps t = delay_taps_f(l.distance[k], inv_bin_f, m_delay, l.ff[k]);
            for (std::uint64_t r = m_row[j]; r < m_row[j + 1]; ++r) {
                const Run& run = m_runs[r];
                if (!taken[run.order]) continue;
                const float* e = m_energy.data() + run.offset;
                const std::int64_t at = run.first + t.lag;  // row bin of the w0 tap of e[0]; w1's is one later
                const std::int64_t length = std::int64_t(run.length);
                if (at + length + 1 <= first_bin || at >= end) continue;
                touched = true;
                // out[b] += w0 e[b - at] for b in [at, at + length), and w1 e[b - at - 1] for b in
                // [at + 1, at + length + 1), both clipped to the fill's bins.
                const auto axpy = [&](float w, std::int64_t from) {
                    const std::int64_t lo = std::max(from, first_bin), hi = std::min(from + length, end);
                    if (lo >= hi || w == 0.0f) return;
                    float* __restrict out = row + std::size_t(lo - first_bin) * 3;
                    const float* __restrict in = e + std::size_t(lo - from) * 3;
                    const std::size_t count = std::size_t(hi - lo) * 3;
                    for (std::size_t q = 0; q < count; ++q) out[q] += w * in[q];
                };
                axpy(t.w0, at);
                axpy(t.w1, at + 1);
            }
        }
        if (!touched) return;
        lit[i] = 1;
        const Rgb& albedo = m_patches.albedo[i];
        for (std::size_t b = 0; b < bins; ++b)
            for (int c = 0; c < 3; ++c) row[b * 3 + std::size_t(c)] *= float(albedo[c]);
    });
}

double SecondBounceLight::shift(std::uint32_t k, const Vec3& x) const {
    const Vec3 d = x - m_patches.centroid[k];
    const std::array<float, 3>& g = m_gradient[k];
    const std::array<float, 6>& h = m_hessian[k];
    const double linear = double(g[0]) * d.x() + double(g[1]) * d.y() + double(g[2]) * d.z();
    const double quadratic = double(h[0]) * d.x() * d.x() + double(h[1]) * d.y() * d.y() + double(h[2]) * d.z() * d.z() +
                             2.0 * (double(h[3]) * d.x() * d.y() + double(h[4]) * d.x() * d.z() + double(h[5]) * d.y() * d.z());
    return linear + 0.5 * quadratic;
}

std::unique_ptr<SecondBounceLight> make_second_bounce_light(const PatchSet& patches, const LinkSet& links,
                                                      const Illumination& illumination, const TimeAxis& time,
                                                      const SecondBounceOptions& options, bool mirrors) {
    if (mirrors || links.links.tinted() || patches.size() == 0) return nullptr;
    auto light = std::make_unique<SecondBounceLight>(patches, links, illumination, time, options);
    if (light->empty()) return nullptr;
    return light;
}

}  // namespace tprf
