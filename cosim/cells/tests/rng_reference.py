"""Second implementation of the cells' generator, for known-answer values.

xoshiro256++ and SplitMix64 as published by Blackman and Vigna (prng.di.unimi.it), the
normal ziggurat of Marsaglia and Tsang (2000, 256 layers, r = 3.6541528853610088,
v = 4.92867323399e-3) with Marsaglia's (1964) tail; Python integers and floats.
"""
import math

M = (1 << 64) - 1

def rotl(x, k):
    return ((x << k) | (x >> (64 - k))) & M

def splitmix64(state):
    state = (state + 0x9E3779B97F4A7C15) & M
    z = state
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & M
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & M
    return state, z ^ (z >> 31)

class Xoshiro:
    def __init__(self, seed):
        s = []
        for _ in range(4):
            seed, v = splitmix64(seed)
            s.append(v)
        self.s = s

    @staticmethod
    def stream(seed, stream):
        _, v = splitmix64(seed ^ ((stream * 0xD1B54A32D192ED03) & M))
        return Xoshiro(v)

    def next(self):
        s = self.s
        result = (rotl((s[0] + s[3]) & M, 23) + s[0]) & M
        t = (s[1] << 17) & M
        s[2] ^= s[0]; s[3] ^= s[1]; s[1] ^= s[2]; s[0] ^= s[3]
        s[2] ^= t
        s[3] = rotl(s[3], 45)
        return result

    def uniform(self):
        return (self.next() >> 11) * 2.0 ** -53

R = 3.654152885361009
V = 4.92867323399e-3

def pdf(x):
    return math.exp(-0.5 * x * x)

X = [0.0] * 257
X[0] = V / pdf(R)
X[1] = R
for i in range(2, 256):
    X[i] = math.sqrt(-2.0 * math.log(V / X[i - 1] + pdf(X[i - 1])))
F = [pdf(x) for x in X]

def normal(g):
    while True:
        bits = g.next()
        i = bits & 0xFF
        u = 2.0 * ((bits >> 11) * 2.0 ** -53) - 1.0
        x = u * X[i]
        if abs(x) < X[i + 1]:
            return x, "fast"
        if i == 0:
            while True:
                tx = math.log(1.0 - g.uniform()) / R
                ty = math.log(1.0 - g.uniform())
                if -2.0 * ty >= tx * tx:
                    return (tx - R if u < 0.0 else R - tx), "tail"
        if F[i + 1] + (F[i] - F[i + 1]) * g.uniform() < math.exp(-0.5 * x * x):
            return x, "wedge"

if __name__ == "__main__":
    # The known answers of cosim/cells/src/rng.rs's tests: `python3 rng_reference.py`.
    g = Xoshiro(0)
    print("Rng::new(0).next_u64():", [hex(g.next()) for _ in range(4)])
    g = Xoshiro.stream(7, 1)
    print("Rng::for_stream(7, 1).next_u64():", [hex(g.next()) for _ in range(4)])
    g = Xoshiro(5)
    print("Rng::new(5).uniform():", [repr(g.uniform()) for _ in range(3)])
    g = Xoshiro(3)
    draws = [normal(g) for _ in range(1265)]
    print("Rng::new(3).normal(), draw: value (path)")
    for n in list(range(8)) + [264, 1264]:
        print(f"  {n}: {draws[n][0]!r} ({draws[n][1]})")
