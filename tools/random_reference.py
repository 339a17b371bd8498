#!/usr/bin/python3
"""Reference values for tests/sensor_test.cpp (Random.*): an independent Python reimplementation of
lib/include/tprf/core/random.h and lib/src/core/random.cpp, written from the specification in
docs/sensor.md ("Noise and reproducibility"), not translated from the C++.

Run once; its output was pasted into the test. Python's floats are IEEE doubles and its math module
calls the C library's log, log1p, exp, sqrt, cos and sin, as the C++ does, without fused
multiply-adds (the C++ file is compiled with -ffp-contract=off), so the doubles agree bit for bit.
"""

import math

MASK = (1 << 64) - 1
GAMMA = 0x9E3779B97F4A7C15


def mix(z):
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & MASK
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & MASK
    return z ^ (z >> 31)


class SplitMix64:
    def __init__(self, seed):
        self.x = seed & MASK

    def next(self):
        self.x = (self.x + GAMMA) & MASK
        return mix(self.x)


def rotl(x, k):
    return ((x << k) | (x >> (64 - k))) & MASK


class Random:
    def __init__(self, seed):
        sm = SplitMix64(seed)
        self.s = [sm.next() for _ in range(4)]
        self.spare = None

    def next_u64(self):
        s = self.s
        result = (rotl((s[1] * 5) & MASK, 7) * 9) & MASK
        t = (s[1] << 17) & MASK
        s[2] ^= s[0]
        s[3] ^= s[1]
        s[1] ^= s[2]
        s[0] ^= s[3]
        s[2] ^= t
        s[3] = rotl(s[3], 45)
        return result

    def uniform(self):
        return (self.next_u64() >> 11) * 2.0**-53

    def normal(self):
        if self.spare is not None:
            v, self.spare = self.spare, None
            return v
        u1 = 1.0 - self.uniform()
        u2 = self.uniform()
        r = math.sqrt(-2.0 * math.log(u1))
        theta = 2.0 * math.pi * u2
        self.spare = r * math.sin(theta)
        return r * math.cos(theta)

    def poisson(self, mean):
        if not mean > 0.0:
            return 0.0
        if mean < 10.0:
            limit = math.exp(-mean)
            count, product = 0.0, self.uniform()
            while product > limit:
                product *= self.uniform()
                count += 1.0
            return count
        log_mean = math.log(mean)
        b = 0.931 + 2.53 * math.sqrt(mean)
        a = -0.059 + 0.02483 * b
        log_alpha = math.log(1.1239 + 1.1328 / (b - 3.4))
        v_r = 0.9277 - 3.6224 / (b - 2.0)
        while True:
            u = self.uniform() - 0.5
            v = self.uniform()
            us = 0.5 - abs(u)
            if us == 0.0:
                continue
            k = float(math.floor((2.0 * a / us + b) * u + mean + 0.43))
            if us >= 0.07 and v <= v_r:
                return k
            if k < 0.0 or (us < 0.013 and v > us):
                continue
            lhs = math.log(v) + log_alpha - math.log(a / (us * us) + b)
            if lhs <= log_pmf(k, mean, log_mean):
                return k


def log_pmf(k, mean, log_mean):
    if k < 16:
        return -mean + k * log_mean - math.log(float(math.factorial(int(k))))
    x = (k - mean) / mean
    h = (1.0 + x) * math.log1p(x) - x
    r = 1.0 / k
    r2 = r * r
    c = r * (1.0 / 12 - r2 * (1.0 / 360 - r2 * (1.0 / 1260 - r2 * (1.0 / 1680))))
    return -mean * h - 0.5 * math.log(2.0 * math.pi * k) - c


def main():
    seed = 1477776061723855037
    print("SplitMix64::output(seed, 5) for pixel streams:", mix((seed + GAMMA * 6) & MASK))
    r = Random(42)
    print("Random(42) next_u64:", [r.next_u64() for _ in range(3)])
    print("uniform:", [r.uniform().hex() for _ in range(2)])
    print("normal:", [r.normal().hex() for _ in range(3)])
    print("poisson(3.5):", [r.poisson(3.5) for _ in range(4)])
    print("poisson(1234.5):", [r.poisson(1234.5) for _ in range(4)])
    print("poisson(1e12):", [r.poisson(1e12) for _ in range(3)])
    print("poisson(1e15):", [r.poisson(1e15) for _ in range(3)])


if __name__ == "__main__":
    main()
