#include "tprf/transport/steady.h"

#include "tprf/transport/illumination.h"
#include "tprf/core/cancel.h"
#include "tprf/core/error.h"
#include "tprf/transport/link_set.h"
#include "tprf/geometry/patches.h"

#include <Eigen/IterativeLinearSolvers>
#include <Eigen/SparseCore>

#include <string>

namespace tprf {
namespace {

// Row sums of the links of node i applied to the node values v in channel c: a tinted link's form
// factor times its tint (Links::tint_factor), in float as the transient solver takes it.
double row_sum(const Links& links, const Eigen::VectorXd& v, std::size_t i, int c) {
    double s = 0.0;
    if (!links.tinted()) {
        for (std::uint64_t k = links.row[i]; k < links.row[i + 1]; ++k) s += double(links.ff[k]) * v[links.source[k]];
        return s;
    }
    for (std::uint64_t k = links.row[i]; k < links.row[i + 1]; ++k)
        s += double(links.ff[k] * links.tint_factor(k, c)) * v[links.source[k]];
    return s;
}

// Glossy out-cell i's lobe over its patch's in-cells in x (glossy_rows.h).
double lobe_sum(const PatchSet& patches, const GlossyRows& rows, const Eigen::VectorXd& x, std::size_t i) {
    const std::size_t m = std::size_t(rows.cells()), j = i - rows.out_begin();
    const float* lobe = rows.lobe_of_patch(patches, j / m);  // in-cell by in-cell
    const Eigen::Index first = Eigen::Index(rows.first_in_of(i));
    double s = 0.0;
    for (std::size_t c = 0; c < m; ++c) s += double(lobe[c * m + j % m]) * x[first + Eigen::Index(c)];
    return s;
}

// y = diag(albedo_c) F_c x for one channel (F_c: the form factors, tinted links' times their tint):
// with clusters, their values pulled from x, every node's gather pushed down to the patches below it
// (link_set.h).
Eigen::VectorXd gather(const PatchSet& patches, const LinkSet& set, const Eigen::VectorXd& x, int c) {
    check_cancelled();  // once per iteration of the solver, outside its parallel loops
    const Eigen::Index n = Eigen::Index(set.patches());
    const ClusterTree& t = set.tree;
    Eigen::VectorXd y(n);
    const std::size_t out_begin = set.glossy.empty() ? std::size_t(n) : set.glossy.out_begin();
    // A row's gathered light: its links, or (a glossy out-cell) its lobe over its in-cells.
    const auto gathered = [&](const Eigen::VectorXd& v, std::size_t i) {
        return i >= out_begin && i < std::size_t(n) ? lobe_sum(patches, set.glossy, x, i) : row_sum(set.links, v, i, c);
    };
    if (t.clusters() == 0) {
#pragma omp parallel for schedule(dynamic, 64)
        for (Eigen::Index i = 0; i < n; ++i) y[i] = set.albedo(patches, std::size_t(i))[c] * gathered(x, std::size_t(i));
        return y;
    }
    const std::size_t m = t.nodes();
    Eigen::VectorXd v = Eigen::VectorXd::Zero(Eigen::Index(m)), g = Eigen::VectorXd::Zero(Eigen::Index(m));
    v.head(n) = x;
    for (std::size_t cl = m; cl-- > t.leaves;) {  // preorder ids backwards: children first
        const auto [a, b] = t.children[cl - t.leaves];
        v[cl] = (t.area[a] * v[a] + t.area[b] * v[b]) / t.area[cl];
    }
#pragma omp parallel for schedule(dynamic, 64)
    for (std::size_t i = 0; i < m; ++i) g[Eigen::Index(i)] = gathered(v, i);
    for (std::size_t cl = t.leaves; cl < m; ++cl)  // preorder ids: parents first
        if (t.parent[cl] != kNoNode) g[Eigen::Index(cl)] += g[t.parent[cl]];
    for (Eigen::Index i = 0; i < n; ++i) {
        const std::uint32_t up = t.parent[std::size_t(i)];
        y[i] = set.albedo(patches, std::size_t(i))[c] * (g[i] + (up == kNoNode ? 0.0 : g[up]));
    }
    return y;
}

}  // namespace

class SteadyOperator;

}  // namespace tprf

template <>
struct Eigen::internal::traits<tprf::SteadyOperator> : public Eigen::internal::traits<Eigen::SparseMatrix<double>> {};

namespace tprf {

/// The system matrix I - diag(albedo_c) F_c of one channel, applied straight from the links (Eigen's
/// matrix-free solver interface): a sparse copy of F would cost 12 more bytes per link, as much again
/// as the links themselves.
class SteadyOperator : public Eigen::EigenBase<SteadyOperator> {
public:
    using Scalar = double;
    using RealScalar = double;
    using StorageIndex = int;
    enum { ColsAtCompileTime = Eigen::Dynamic, MaxColsAtCompileTime = Eigen::Dynamic, IsRowMajor = false };

    SteadyOperator(const PatchSet& patches, const LinkSet& links, int channel)
        : m_patches(patches), m_links(links), m_channel(channel) {}

    Eigen::Index rows() const { return Eigen::Index(m_links.patches()); }
    Eigen::Index cols() const { return Eigen::Index(m_links.patches()); }

    template <typename Rhs>
    Eigen::Product<SteadyOperator, Rhs, Eigen::AliasFreeProduct> operator*(const Eigen::MatrixBase<Rhs>& x) const {
        return Eigen::Product<SteadyOperator, Rhs, Eigen::AliasFreeProduct>(*this, x.derived());
    }

    /// (I - diag(albedo_c) F_c) x.
    Eigen::VectorXd apply(const Eigen::VectorXd& x) const { return x - gather(m_patches, m_links, x, m_channel); }

private:
    const PatchSet& m_patches;
    const LinkSet& m_links;
    int m_channel;
};

}  // namespace tprf

namespace Eigen::internal {

template <typename Rhs>
struct generic_product_impl<tprf::SteadyOperator, Rhs, SparseShape, DenseShape, GemvProduct>
    : generic_product_impl_base<tprf::SteadyOperator, Rhs, generic_product_impl<tprf::SteadyOperator, Rhs>> {
    using Scalar = typename Product<tprf::SteadyOperator, Rhs>::Scalar;
    template <typename Dest>
    static void scaleAndAddTo(Dest& dst, const tprf::SteadyOperator& lhs, const Rhs& rhs, const Scalar& alpha) {
        dst.noalias() += alpha * lhs.apply(rhs);
    }
};

}  // namespace Eigen::internal

namespace tprf {

std::vector<Rgb> solve_steady(const PatchSet& patches, const LinkSet& links, const Illumination& emission,
                              int max_bounces) {
    const std::size_t n = links.patches();  // the patches and the glossy rows
    TPRF_CHECK_EQ(links.surface_patches(), patches.size());
    TPRF_CHECK_EQ(emission.row.size(), n + 1);
    TPRF_CHECK_EQ(links.links.receivers(), links.nodes());
    check_tints(links.links);
    int max_order = 0;
    for (const Pulse& p : emission.pulses) max_order = std::max(max_order, int(p.order));
    // Time-integrated emission per order (a pulse's energy is its whole contribution).
    std::vector<std::vector<Rgb>> by_order(std::size_t(max_order) + 1, std::vector<Rgb>(n, Rgb::Zero()));
    std::vector<Rgb> seen_only(n, Rgb::Zero());
    for (std::size_t i = 0; i < n; ++i)
        for (std::uint64_t k = emission.row[i]; k < emission.row[i + 1]; ++k) {
            const Pulse& p = emission.pulses[k];
            if (max_bounces >= 0 && p.order > max_bounces) continue;
            (p.propagates ? by_order[p.order][i] : seen_only[i]) += p.energy;
        }

    std::vector<Rgb> b(n, Rgb::Zero());
    for (int c = 0; c < 3; ++c) {
        Eigen::VectorXd result;
        if (max_bounces >= 0) {
            // Neumann series up to max_bounces: R_k = E_k + diag(a) F R_{k-1}.
            Eigen::VectorXd r = Eigen::VectorXd::Zero(Eigen::Index(n));
            result = Eigen::VectorXd::Zero(Eigen::Index(n));
            for (int k = 0; k <= max_bounces; ++k) {
                Eigen::VectorXd next = k > 0 ? gather(patches, links, r, c) : Eigen::VectorXd::Zero(Eigen::Index(n));
                if (k <= max_order)
                    for (std::size_t i = 0; i < n; ++i) next[Eigen::Index(i)] += by_order[std::size_t(k)][i][c];
                // Glossy out-cells pass on this order's light that their in-cells gathered (glossy_rows.h).
                for (std::size_t i = links.glossy.out_begin(); k > 0 && !links.glossy.empty() && i < n; ++i)
                    next[Eigen::Index(i)] = (k <= max_order ? by_order[std::size_t(k)][i][c] : 0.0) +
                                            links.albedo(patches, i)[c] * lobe_sum(patches, links.glossy, next, i);
                r = std::move(next);
                result += r;
            }
        } else {
            Eigen::VectorXd e = Eigen::VectorXd::Zero(Eigen::Index(n));
            for (const auto& order : by_order)
                for (std::size_t i = 0; i < n; ++i) e[Eigen::Index(i)] += order[i][c];
            if (e.squaredNorm() == 0.0) {
                result = e;
            } else {
                // A patch never links to itself, so the diagonal is 1 and needs no preconditioner.
                const SteadyOperator m(patches, links, c);
                Eigen::BiCGSTAB<SteadyOperator, Eigen::IdentityPreconditioner> solver;
                solver.setTolerance(1e-8);
                solver.setMaxIterations(10000);
                solver.compute(m);
                result = solver.solve(e);
                if (solver.info() != Eigen::Success)
                    throw InternalError("steady state: BiCGSTAB did not converge (relative residual " +
                                        std::to_string(solver.error()) + ")");
            }
        }
        for (std::size_t i = 0; i < n; ++i) b[i][c] = result[Eigen::Index(i)] + seen_only[i][c];
    }
    return b;
}

}  // namespace tprf
