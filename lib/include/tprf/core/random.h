#pragma once
/// Random numbers that are the same on every platform: a specified generator and specified transforms,
/// instead of <random>'s distributions, whose algorithms each standard library chooses for itself (a
/// seed gives other noise with libc++ than with libstdc++). docs/sensor.md, "Noise and reproducibility".
///
/// - SplitMix64 (Steele, Lea and Flood, "Fast splittable pseudorandom number generators", OOPSLA
///   2014; the reference code is Vigna's https://prng.di.unimi.it/splitmix64.c) turns one 64-bit seed
///   into well-mixed stream seeds and generator states.
/// - xoshiro256** 1.0 (Blackman and Vigna, "Scrambled linear pseudorandom number generators", ACM
///   TOMS 47(4), 2021; reference code https://prng.di.unimi.it/xoshiro256starstar.c) draws the
///   numbers; its state is the first four SplitMix64 outputs of the stream's seed, as its authors
///   recommend.
/// - Uniform doubles are the top 53 bits times 2^-53, in [0, 1).
/// - Normals: Box-Muller (the cosine value first, then the sine value of the same pair).
/// - Poisson counts: the multiplication method below a mean of 10, Hormann's transformed rejection
///   with squeeze (PTRS) from 10 on.
///
/// The integers and the uniform doubles are bit-identical everywhere. The normals and the Poisson counts
/// also use log, log1p, sqrt, cos and sin: they are identical wherever the C library's results of those
/// agree (sqrt is exact everywhere; glibc's log, cos and sin are correctly rounded in practice).

#include <array>
#include <cmath>
#include <cstdint>

namespace tprf {

/// SplitMix64: state += 0x9E3779B97F4A7C15, output = a bijective mix of the state.
class SplitMix64 {
public:
    explicit SplitMix64(std::uint64_t seed) : m_state(seed) {}
    /// The next output.
    std::uint64_t next() {
        m_state += kGamma;
        return mix(m_state);
    }
    /// Output number `index` (0-based) of the stream seeded with `seed`, without stepping through the
    /// outputs before it: one independent seed per pixel from one user seed.
    static std::uint64_t output(std::uint64_t seed, std::uint64_t index) { return mix(seed + kGamma * (index + 1)); }

private:
    static constexpr std::uint64_t kGamma = 0x9E3779B97F4A7C15ull;
    static std::uint64_t mix(std::uint64_t z) {
        z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
        z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
        return z ^ (z >> 31);
    }
    std::uint64_t m_state;
};

/// xoshiro256**: 256 bits of state (never all zero), period 2^256 - 1.
class Xoshiro256StarStar {
public:
    /// The state as given (the reference tests); it must not be all zero.
    explicit Xoshiro256StarStar(const std::array<std::uint64_t, 4>& state) : m_s(state) {}
    /// The state from the first four outputs of SplitMix64(seed) (never all zero: SplitMix64's outputs
    /// over four consecutive states are distinct).
    explicit Xoshiro256StarStar(std::uint64_t seed) {
        SplitMix64 sm(seed);
        for (std::uint64_t& s : m_s) s = sm.next();
    }
    /// The next output.
    std::uint64_t next() {
        const std::uint64_t result = rotl(m_s[1] * 5, 7) * 9;
        const std::uint64_t t = m_s[1] << 17;
        m_s[2] ^= m_s[0];
        m_s[3] ^= m_s[1];
        m_s[1] ^= m_s[2];
        m_s[0] ^= m_s[3];
        m_s[2] ^= t;
        m_s[3] = rotl(m_s[3], 45);
        return result;
    }

private:
    static std::uint64_t rotl(std::uint64_t x, int k) { return (x << k) | (x >> (64 - k)); }
    std::array<std::uint64_t, 4> m_s{};
};

/// One stream of random numbers: a xoshiro256** generator and the transforms that tprf specifies.
/// Not thread-safe; give each pixel (or each task) its own stream.
class Random {
public:
    /// The generator's state from SplitMix64(seed).
    explicit Random(std::uint64_t seed) : m_gen(seed) {}

    /// The generator's next 64-bit output.
    std::uint64_t next_u64() { return m_gen.next(); }

    /// Uniform in [0, 1): the top 53 bits of the next output times 2^-53 (every value a multiple of 2^-53).
    double uniform() { return double(m_gen.next() >> 11) * 0x1.0p-53; }

    /// Standard normal (mean 0, variance 1) by Box-Muller: u1 = 1 - uniform() in (0, 1], u2 = uniform(),
    /// r = sqrt(-2 log u1); returns r cos(2 pi u2) and keeps r sin(2 pi u2), which the next call returns
    /// without drawing.
    double normal();

    /// A Poisson count (a whole number, as a double) of mean `mean` in [0, 2^52]; 0 for a mean <= 0.
    /// Below 10: the multiplication method (Knuth, TAOCP vol. 2, 3.4.1): the number of uniform() factors
    /// whose product stays above exp(-mean), about mean + 1 draws. From 10 on: PTRS (W. Hormann, "The
    /// transformed rejection method for generating Poisson random variables", Insurance: Mathematics and
    /// Economics 12, 1993), two uniform() per try, 1.1 to 1.3 tries on average; its acceptance test is
    /// evaluated in a form without cancellation (docs/sensor.md), so it stays exact up to the largest means.
    double poisson(double mean);

    /// v + sigma * normal(), rounded in two steps: random.cpp is compiled without fused multiply-add,
    /// so the noisy value is the same on every build whatever -march allows.
    double add_normal(double v, double sigma);

private:
    Xoshiro256StarStar m_gen;
    double m_spare = 0.0;
    bool m_has_spare = false;
};

/// A SPAD's expected counts, photons * max(0, signal) + dark, rounded in two steps on every build (no
/// fused multiply-add), so that the Poisson draw that follows sees the same mean everywhere.
double expected_counts(double photons, double signal, double dark);

/// Point k of the R2 low-discrepancy sequence in the unit square (Roberts, "The unreasonable
/// effectiveness of quasirandom sequences", 2018): ((0.5 + k / phi2) mod 1, (0.5 + k / phi2^2) mod 1),
/// phi2 the plastic number. Any prefix of it is well spread: it stratifies any count of samples. For
/// k >= 0, x - floor(x) is exactly fmod(x, 1) (the fraction's bits), at a fraction of its cost.
inline void r2_point(double k, double& u, double& v) {
    const double x = 0.5 + 0.7548776662466927 * k, y = 0.5 + 0.5698402909980532 * k;
    u = k >= 0.0 ? x - std::floor(x) : std::fmod(x, 1.0);
    v = k >= 0.0 ? y - std::floor(y) : std::fmod(y, 1.0);
}

}  // namespace tprf
