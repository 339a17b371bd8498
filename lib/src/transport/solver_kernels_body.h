// The long-link kernels of the transient march and their tables, written once and compiled once per
// instruction set: solver_kernels.cpp includes this file inside a namespace of its own for each, with
// TPRF_KERNEL_TARGET defined as that set's function attribute (empty for the library's own). Everything
// here has internal linkage, so no copy compiled for a wider set can stand in for another at link time.
// No include guard: it is meant to be included more than once.

namespace {

// A kernel's sums into the accumulators: bin b's C lanes at acc + b * stride, one stream where the
// bins are contiguous (a receiver tile's own sums).
inline TPRF_KERNEL_TARGET void add_sums(float* __restrict acc, std::size_t stride, const float* __restrict local, int C,
                                        int BT) {
    if (stride == std::size_t(C)) {
        for (int e = 0; e < C * BT; ++e) acc[e] += local[e];
        return;
    }
    for (int b = 0; b < BT; ++b)
        for (int c = 0; c < C; ++c) acc[std::size_t(b) * stride + std::size_t(c)] += local[b * C + c];
}

// Links ahead whose source history the long-link kernel prefetches.
constexpr std::uint64_t kAhead = 8;

// The long-link kernel for one receiver and one source tile: the block's sums stay in registers
// (C * BT floats) across all the receiver's links, and go to memory once at the end.
template <int C, int BT>
TPRF_KERNEL_TARGET void gather_long(const Links& links, std::uint64_t& cursor, std::uint64_t end, std::uint32_t source_end, float inv_bin,
                 DelayMode mode, const float* ring, const RingSlot* slots, std::int64_t b0, float* acc,
                 std::size_t stride) {
    // Locals, not the reference and the vectors: a store through `cursor` would make the compiler
    // reload every array pointer once per link.
    const std::uint32_t* __restrict source = links.source.data();
    const float* __restrict distance = links.distance.data();
    const float* __restrict ff = links.ff.data();
    float local[C * BT] = {};
    std::uint64_t k = cursor;
    for (; k < end && source[k] < source_end; ++k) {
        // Sparse rows (hierarchical sets) read a scattered ring per link: ask for the one kAhead links
        // on, and for the slot of the one after that, while this link is summed.
        if (k + 2 * kAhead < end) {
            __builtin_prefetch(&slots[source[k + 2 * kAhead]]);
            const RingSlot& next = slots[source[k + kAhead]];
            const int lag = int(distance[k + kAhead] * inv_bin);
            const float* at = ring + next.offset + std::size_t(int((b0 - lag - 1) & next.mask)) * C;
            for (int line = 0; line < (C * (BT + 1) * 4 + 63) / 64 && line < 4; ++line)
                __builtin_prefetch(at + 16 * line);
        }
        const Taps t = link_taps(distance[k], inv_bin, mode, ff[k]);
        if (t.lag < BT) continue;
        const RingSlot& slot = slots[source[k]];
        const float* __restrict h = ring + slot.offset + std::size_t(int((b0 - t.lag - 1) & slot.mask)) * C;
        // Two separate accumulations: written as one sum, the compiler (no -ffast-math) must round
        // w0 h + w1 h first, which costs a multiply, an FMA and an add instead of two FMAs.
        for (int e = 0; e < C * BT; ++e) {
            local[e] += t.w0 * h[e + C];
            local[e] += t.w1 * h[e];
        }
    }
    if (k == cursor) return;  // no link of this window in this source tile: nothing to add
    cursor = k;
    add_sums(acc, stride, local, C, BT);
}

// The same for any lane count C and windows of BT bins: the sums (C * BT floats) in a local array,
// each link one contiguous multiply-add over it, which vectorises over bins and lanes alike.
template <int BT>
TPRF_KERNEL_TARGET void gather_lanes(const Links& links, std::uint64_t& cursor, std::uint64_t end, std::uint32_t source_end,
                  float inv_bin, DelayMode mode, const float* ring, const RingSlot* slots, std::int64_t b0, int C,
                  float* acc, std::size_t stride) {
    const std::uint32_t* __restrict source = links.source.data();
    const float* __restrict distance = links.distance.data();
    const float* __restrict ff = links.ff.data();
    const int len = C * BT;
    float local[kMaxLanes * BT];
    std::fill_n(local, len, 0.0f);
    std::uint64_t k = cursor;
    for (; k < end && source[k] < source_end; ++k) {
        if (k + 2 * kAhead < end) {  // as in gather_long
            __builtin_prefetch(&slots[source[k + 2 * kAhead]]);
            const RingSlot& next = slots[source[k + kAhead]];
            const int lag = int(distance[k + kAhead] * inv_bin);
            const float* at = ring + next.offset + std::size_t(int((b0 - lag - 1) & next.mask)) * std::size_t(C);
            for (int line = 0; line < 4; ++line) __builtin_prefetch(at + 16 * line);
        }
        const Taps t = link_taps(distance[k], inv_bin, mode, ff[k]);
        if (t.lag < BT) continue;
        const RingSlot& slot = slots[source[k]];
        const float* __restrict h = ring + slot.offset + std::size_t(int((b0 - t.lag - 1) & slot.mask)) * std::size_t(C);
        for (int e = 0; e < len; ++e) {  // two accumulations, as in gather_long
            local[e] += t.w0 * h[e + C];
            local[e] += t.w1 * h[e];
        }
    }
    if (k == cursor) return;
    cursor = k;
    add_sums(acc, stride, local, C, BT);
}

// The shortest window's links (SolvePlan::recent_kernel) of one receiver, [k0, k1) of the
// near list, for CT lanes (0: C, counted at run time): as gather_long, each bin of a source's window read
// from the recent bins instead of its ring, with the taps the plan made.
template <int CT, int BT>
TPRF_KERNEL_TARGET void gather_recent(const NearLinks& near, std::uint64_t k0, std::uint64_t k1, const RecentView& recent,
                   std::int64_t b0, int lanes, float* acc, std::size_t stride) {
    if (k0 == k1) return;
    const TapLink* __restrict links = near.links.data();
    const int C = CT > 0 ? CT : lanes;
    float local[(CT > 0 ? CT : kMaxLanes) * BT];
    std::fill_n(local, C * BT, 0.0f);
    auto at = [&](std::int64_t bin, std::uint32_t q) {
        return recent.data + std::size_t(int(bin & recent.mask)) * recent.slice + std::size_t(q) * std::size_t(C);
    };
    for (std::uint64_t k = k0; k < k1; ++k) {
        if (k + kAhead < k1 && BT <= 2) {  // the window's bins kAhead links on, each in its own bin's slice
            const TapLink& ahead = links[k + kAhead];
            const std::int64_t first = b0 - ahead.lag - 1;
            for (int b = 0; b <= BT; ++b) __builtin_prefetch(at(first + b, ahead.source));
        }
        const TapLink t = links[k];
        const std::int64_t first = b0 - t.lag - 1;
        const float* __restrict h = at(first, t.source);
        for (int b = 0; b < BT; ++b) {
            const float* __restrict next = at(first + b + 1, t.source);
            for (int c = 0; c < C; ++c) {  // two accumulations, as in gather_long
                local[b * C + c] += t.w0 * next[c];
                local[b * C + c] += t.w1 * h[c];
            }
            h = next;
        }
    }
    add_sums(acc, stride, local, C, BT);
}

template <int BT>
RecentKernel recent_for_lanes(int C) {
    switch (C) {
        case 1: return gather_recent<1, BT>;
        case 3: return gather_recent<3, BT>;
        case 8: return gather_recent<8, BT>;
        case 16: return gather_recent<16, BT>;
        default: return gather_recent<0, BT>;
    }
}

RecentKernel recent_table(int C, int bins) {
    switch (bins) {
        case 1: return recent_for_lanes<1>(C);
        case 2: return recent_for_lanes<2>(C);
        case 4: return recent_for_lanes<4>(C);
        case 8: return recent_for_lanes<8>(C);
        case 16: return recent_for_lanes<16>(C);
        default: return nullptr;
    }
}

// The long-link kernel for C channels and windows of `bins` bins (the block's and the longer
// windows up to kLongestWindow), or null for the generic one.
template <int C>
GatherKernel kernel_for(int bins) {
    switch (bins) {
        case 1: return gather_long<C, 1>;
        case 2: return gather_long<C, 2>;
        case 4: return gather_long<C, 4>;
        case 8: return gather_long<C, 8>;
        case 16: return gather_long<C, 16>;
        case 32: return gather_long<C, 32>;
        case 64:  // grey scenes only: 3 x 64 sums do not fit in registers
            if constexpr (C == 1) return gather_long<C, 64>;
            return nullptr;
        default: return nullptr;
    }
}

GatherKernel long_table(int C, int bins) {
    switch (C) {
        case 1: return kernel_for<1>(bins);
        case 3: return kernel_for<3>(bins);
        case 8: return kernel_for<8>(bins);
        case 16: return kernel_for<16>(bins);
        default: return nullptr;
    }
}

LaneKernel lane_table(int bins) {
    switch (bins) {
        case 1: return gather_lanes<1>;
        case 2: return gather_lanes<2>;
        case 4: return gather_lanes<4>;
        case 8: return gather_lanes<8>;
        case 16: return gather_lanes<16>;
        case 32: return gather_lanes<32>;
        default: return nullptr;
    }
}

}  // namespace
