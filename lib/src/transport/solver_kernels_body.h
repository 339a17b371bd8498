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
TPRF_KERNEL_TARGET void gather_long(const LongCall& call) {
    // Locals, not the call's fields, the reference and the vectors: a store through `cursor` or `acc`
    // would make the compiler reload them once per link.
    const Links& links = *call.links;
    std::uint64_t& cursor = *call.cursor;
    const std::uint64_t end = call.end;
    const std::uint32_t source_end = call.source_end;
    const float inv_bin = call.inv_bin;
    const DelayMode mode = call.mode;
    const float* const ring = call.ring;
    const RingSlot* const slots = call.slots;
    const std::int64_t b0 = call.b0;
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
            const int lag = delay_bins_f(distance[k + kAhead], inv_bin);
            const float* at = ring + next.offset + std::size_t(int((b0 - lag - 1) & next.mask)) * C;
            for (int line = 0; line < (C * (BT + 1) * 4 + 63) / 64 && line < 4; ++line)
                __builtin_prefetch(at + 16 * line);
        }
        const DelayTaps t = delay_taps_f(distance[k], inv_bin, mode, ff[k]);
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
    add_sums(call.acc, call.stride, local, C, BT);
}

// The packed kernel's vectors: 16 floats for AVX-512, 8 for the library's own set (AVX2). Each sum is
// the same chain of operations on one float either way, so both give the same bits.
#ifdef TPRF_KERNEL_WIDE
constexpr int kPackedWidth = 16;
#else
constexpr int kPackedWidth = 8;
#endif

// Parts of a window of BT bins that a packed kernel of vectors of W floats with `registers` for its
// sums sums one after the other (a power of two): the fewest whose sums fit, or 0.
constexpr int parts_for(int C, int BT, int W, int registers) {
    for (int P = 1; P <= BT; P *= 2) {
        const int floats = C * (BT / P);
        if (floats % W != 0) continue;
        const int sums = floats / W + (floats + C + W - 1) / W;
        if (sums <= registers) return P;
    }
    return 0;
}

// The parts of this copy's kernel, or 0 for no packed kernel. Which (C, BT) have one does not depend on
// the instruction set (C x BT a multiple of 16 floats, and both copies' sums fit: the AVX-512 one's in
// 28 of its 32 registers, beside two taps and a window vector, the AVX2 one's in 13 of 16), so that a
// plan packs the same links either way.
constexpr int packed_parts(int C, int BT) {
    if ((C * BT) % 16 != 0 || parts_for(C, BT, 16, 28) == 0 || parts_for(C, BT, 8, 13) == 0) return 0;
    return kPackedWidth == 16 ? parts_for(C, BT, 16, 28) : parts_for(C, BT, 8, 13);
}

// The packed kernel for one receiver, one source tile and windows of BT bins (dense rows: flat links),
// every source's ring `ring_floats` floats long (SolvePlan::packed_ring) and `mask` + 1 bins before its mirror.
// Split taps: each vector of a source's window is loaded once and multiplied into two sets of sums,
// A by w1 (the window as it is) and B by w0 (its bins one later: B is read C lanes on at the end), so a
// link loads C (BT + 1) floats once where two shifted windows would load them twice, and nearly every
// load of a window (at a lag times C floats) spans two cache lines. A window too long for the
// registers is summed in parts, each over all the tile's links.
template <int C, int BT>
TPRF_KERNEL_TARGET void gather_packed(const PackedCall& call) {
    const PackedLink* __restrict links = call.links;
    std::uint64_t& cursor = *call.cursor;
    const std::uint64_t end = call.end, key_end = call.key_end;
    const int lag_bits = call.lag_bits, mask = call.mask;
    const float* const ring = call.ring;
    const std::size_t ring_floats = call.ring_floats, stride = call.stride;
    const std::int64_t b0 = call.b0;
    float* const acc = call.acc;
    constexpr int W = kPackedWidth, P = packed_parts(C, BT), BP = BT / P;
    static_assert(P > 0, "no packed kernel for these lanes and window");
    constexpr int NA = C * BP / W, NB = (C * (BP + 1) + W - 1) / W;
    // B read C lanes on: vector j + C / W, lanes C % W on, joined with the next one where C % W > 0.
    constexpr int Q = C / W, R = C % W;
    typedef float vec __attribute__((vector_size(W * sizeof(float))));
    // (GCC 12 and clang both have __builtin_shufflevector; a macro, not a lambda, which would not have the
    // kernel's target.)
#ifdef TPRF_KERNEL_WIDE
#define TPRF_SHIFTED(j)                                                                                         \
    (R == 0 ? B[(j) + Q]                                                                                        \
            : __builtin_shufflevector(B[(j) + Q], B[(j) + Q + (R > 0)], R, R + 1, R + 2, R + 3, R + 4, R + 5, \
                                      R + 6, R + 7, R + 8, R + 9, R + 10, R + 11, R + 12, R + 13, R + 14, R + 15))
#else
#define TPRF_SHIFTED(j)                                                                                      \
    (R == 0 ? B[(j) + Q]                                                                                     \
            : __builtin_shufflevector(B[(j) + Q], B[(j) + Q + (R > 0)], R, R + 1, R + 2, R + 3, R + 4, R + 5, \
                                      R + 6, R + 7))
#endif
    const std::uint32_t lag_mask = (std::uint32_t(1) << lag_bits) - 1;
    const std::uint64_t first = cursor;
    std::uint64_t last = end;  // the tile's links: [first, last), found by the first part
    for (int part = 0; part < P; ++part) {
        vec A[NA], B[NB];
        for (int j = 0; j < NA; ++j) A[j] = vec{};
        for (int j = 0; j < NB; ++j) B[j] = vec{};
        for (std::uint64_t k = first; k < last; ++k) {
            const PackedLink l = links[k];
            if (part == 0 && l.key >= key_end) {
                last = k;
                break;
            }
            const int lag = int(l.key & lag_mask);  // at least BT: pack_links sorts links by window
            const float* h = ring + std::size_t(l.key >> lag_bits) * ring_floats +
                             std::size_t(int((b0 - lag - 1) & mask)) * C + part * C * BP;
            for (int j = 0; j < NB; ++j) {
                vec v;
                __builtin_memcpy(&v, h + W * j, sizeof v);
#ifdef TPRF_KERNEL_WIDE
                asm("" : "+v"(v));  // one load a vector: GCC would fold it into both multiply-adds
#endif
                if (j < NA) A[j] += l.w1 * v;
                B[j] += l.w0 * v;
            }
        }
        // Each sum's w0 part is B's lanes C on.
        float* to = acc + std::size_t(part * BP) * (stride == std::size_t(C) ? std::size_t(C) : stride);
        if (stride == std::size_t(C)) {  // a receiver tile's own sums: contiguous
            for (int j = 0; j < NA; ++j) {
                vec sum;
                __builtin_memcpy(&sum, to + W * j, sizeof sum);
                sum += A[j] + TPRF_SHIFTED(j);
                __builtin_memcpy(to + W * j, &sum, sizeof sum);
            }
            continue;
        }
        float local[C * BP];
        for (int j = 0; j < NA; ++j) {
            const vec out = A[j] + TPRF_SHIFTED(j);
            __builtin_memcpy(local + W * j, &out, sizeof out);
        }
        add_sums(to, stride, local, C, BP);
    }
    cursor = last;
#undef TPRF_SHIFTED
}

template <int C>
PackedKernel packed_for(int bins) {
    auto pick = []<int BT>() -> PackedKernel {
        if constexpr (packed_parts(C, BT) > 0) return gather_packed<C, BT>;
        return nullptr;
    };
    switch (bins) {
        case 8: return pick.template operator()<8>();
        case 16: return pick.template operator()<16>();
        case 32: return pick.template operator()<32>();
        case 64: return pick.template operator()<64>();
        default: return nullptr;
    }
}

// One illumination grey or coloured, and batches of 8 or 16 grey lanes or 8 coloured illuminations (24
// lanes). 48 lanes' sums fit no AVX2 registers (and run on gather_lanes).
PackedKernel packed_table(int C, int bins) {
    switch (C) {
        case 1: return packed_for<1>(bins);
        case 3: return packed_for<3>(bins);
        case 8: return packed_for<8>(bins);
        case 16: return packed_for<16>(bins);
        case 24: return packed_for<24>(bins);
        default: return nullptr;
    }
}

// The same for any lane count C and windows of BT bins: the sums (C * BT floats) in a local array,
// each link one contiguous multiply-add over it, which vectorises over bins and lanes alike.
template <int BT>
TPRF_KERNEL_TARGET void gather_lanes(const LongCall& call) {
    const Links& links = *call.links;
    std::uint64_t& cursor = *call.cursor;
    const std::uint64_t end = call.end;
    const std::uint32_t source_end = call.source_end;
    const float inv_bin = call.inv_bin;
    const DelayMode mode = call.mode;
    const float* const ring = call.ring;
    const RingSlot* const slots = call.slots;
    const std::int64_t b0 = call.b0;
    const int C = call.lanes;
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
            const int lag = delay_bins_f(distance[k + kAhead], inv_bin);
            const float* at = ring + next.offset + std::size_t(int((b0 - lag - 1) & next.mask)) * std::size_t(C);
            for (int line = 0; line < 4; ++line) __builtin_prefetch(at + 16 * line);
        }
        const DelayTaps t = delay_taps_f(distance[k], inv_bin, mode, ff[k]);
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
    add_sums(call.acc, call.stride, local, C, BT);
}

// The shortest window's links (SolvePlan::recent_kernel) of one receiver, [k0, k1) of the
// near list, for CT lanes (0: C, counted at run time): as gather_long, each bin of a source's window read
// from the recent bins instead of its ring, with the taps the plan made.
template <int CT, int BT>
TPRF_KERNEL_TARGET void gather_recent(const RecentCall& call) {
    const std::uint64_t k0 = call.first, k1 = call.last;
    if (k0 == k1) return;
    const TapLink* __restrict links = call.near->links.data();
    const RecentView recent = call.recent;
    const std::int64_t b0 = call.b0;
    const int C = CT > 0 ? CT : call.lanes;
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
    add_sums(call.acc, call.stride, local, C, BT);
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
