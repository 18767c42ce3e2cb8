// VAMP's own Panda checks on inputs written by benchmarks/bench_panda.py (command `vamp`):
// the discretised motion check at VAMP's resolution (validate_motion<Panda, rake, 32>, the
// check its planners run) and the validity of states in blocks of `rake` (fkcc<rake>, the
// SIMD batch its motion check is made of). No Python in the timed loops.
//
// Build (bench_panda.py does this; VAMP's sources: the vamp-planner sdist, Eigen 3.4):
//   g++ -O3 -march=native -std=c++17 -DNDEBUG -I<vamp>/src/impl -I<eigen3> \
//       benchmarks/vamp_harness.cpp -o vamp_harness
// Run:  vamp_harness <input.bin> <output.bin> <repeats>
//
// input (little-endian): int32 n_spheres, n_cuboids, n_capsules, n_motions, n_states; float32
// spheres (n, 4: x y z r), cuboids (n, 9: centre, euler xyz, half extents), capsules (n, 8:
// centre, euler xyz, radius, length), motions a (n, 7), b (n, 7), states (n, 7).
// output: uint8 free per motion, uint8 valid per state, then float64 median seconds of one
// pass over all motions and of one pass over all states.
#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <vector>

#include <vamp/collision/factory.hh>
#include <vamp/planning/validate.hh>
#include <vamp/robots/panda.hh>

using Robot = vamp::robots::Panda;
static constexpr std::size_t rake = vamp::FloatVectorWidth;
using EnvironmentVector = vamp::collision::Environment<vamp::FloatVector<rake>>;

template <typename T>
static std::vector<T> read(std::FILE *f, std::size_t n)
{
    std::vector<T> out(n);
    if (n && std::fread(out.data(), sizeof(T), n, f) != n)
    {
        std::fprintf(stderr, "vamp_harness: short input\n");
        std::exit(2);
    }
    return out;
}

static double median(std::vector<double> v)
{
    std::sort(v.begin(), v.end());
    return v[v.size() / 2];
}

int main(int argc, char **argv)
{
    if (argc != 4)
    {
        std::fprintf(stderr, "usage: vamp_harness <input.bin> <output.bin> <repeats>\n");
        return 2;
    }
    std::FILE *in = std::fopen(argv[1], "rb");
    if (!in)
    {
        std::fprintf(stderr, "vamp_harness: cannot read %s\n", argv[1]);
        return 2;
    }
    auto counts = read<std::int32_t>(in, 5);
    const std::size_t ns = counts[0], nc = counts[1], np = counts[2], nm = counts[3], nq = counts[4];
    auto spheres = read<float>(in, ns * 4);
    auto cuboids = read<float>(in, nc * 9);
    auto capsules = read<float>(in, np * 8);
    auto a = read<float>(in, nm * 7);
    auto b = read<float>(in, nm * 7);
    auto q = read<float>(in, nq * 7);
    std::fclose(in);

    namespace vf = vamp::collision::factory;
    vamp::collision::Environment<float> env;
    for (std::size_t i = 0; i < ns; ++i)
    {
        const float *s = &spheres[4 * i];
        env.spheres.emplace_back(vf::sphere::flat(s[0], s[1], s[2], s[3]));
    }
    for (std::size_t i = 0; i < nc; ++i)
    {
        const float *c = &cuboids[9 * i];
        auto box = vf::cuboid::flat(c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7], c[8]);
        (box.axis_3_z == 1. ? env.z_aligned_cuboids : env.cuboids).emplace_back(box);
    }
    for (std::size_t i = 0; i < np; ++i)
    {
        const float *c = &capsules[8 * i];
        auto cap = vf::cylinder::center::flat(c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]);
        (cap.xv == 0. and cap.yv == 0. ? env.z_aligned_capsules : env.capsules).emplace_back(cap);
    }
    env.sort();
    const EnvironmentVector ev(env);

    auto config = [](const std::vector<float> &x, std::size_t i)
    {
        std::array<float, Robot::dimension> c;
        std::copy_n(&x[Robot::dimension * i], Robot::dimension, c.begin());
        return Robot::Configuration(c);
    };
    std::vector<Robot::Configuration> ca, cb;
    for (std::size_t i = 0; i < nm; ++i)
    {
        ca.push_back(config(a, i));
        cb.push_back(config(b, i));
    }
    // states in blocks of `rake` (the last block padded with its first state)
    const std::size_t nblocks = (nq + rake - 1) / rake;
    std::vector<Robot::ConfigurationBlock<rake>> blocks(nblocks);
    for (std::size_t k = 0; k < nblocks; ++k)
    {
        for (std::size_t j = 0; j < Robot::dimension; ++j)
        {
            alignas(32) std::array<float, rake> lane;
            for (std::size_t l = 0; l < rake; ++l)
            {
                const std::size_t i = std::min(k * rake + l, nq - 1);
                lane[l] = q[Robot::dimension * i + j];
            }
            blocks[k][j] = vamp::FloatVector<rake>(lane);
        }
    }

    std::vector<std::uint8_t> free(nm), valid(nq);
    const int repeats = std::max(1, std::atoi(argv[3]));
    std::vector<double> t_motion, t_state;
    using clock = std::chrono::steady_clock;
    for (int r = 0; r < repeats; ++r)
    {
        auto t0 = clock::now();
        for (std::size_t i = 0; i < nm; ++i)
        {
            free[i] = vamp::planning::validate_motion<Robot, rake, Robot::resolution>(ca[i], cb[i], ev);
        }
        auto t1 = clock::now();
        std::size_t ok = 0;
        for (std::size_t k = 0; k < nblocks; ++k)
        {
            ok += Robot::fkcc<rake>(ev, blocks[k]);
        }
        auto t2 = clock::now();
        t_motion.push_back(std::chrono::duration<double>(t1 - t0).count());
        t_state.push_back(std::chrono::duration<double>(t2 - t1).count());
        if (ok > nblocks)
        {
            return 3;  // never: keeps the loop's result alive
        }
    }
    // per-state validity (outside the timing): a block of one state broadcast to every lane
    for (std::size_t i = 0; i < nq; ++i)
    {
        auto c = config(q, i);
        valid[i] = vamp::planning::validate_motion<Robot, rake, 1>(c, c, ev);
    }
    std::FILE *out = std::fopen(argv[2], "wb");
    if (!out)
    {
        std::fprintf(stderr, "vamp_harness: cannot write %s\n", argv[2]);
        return 2;
    }
    std::fwrite(free.data(), 1, nm, out);
    std::fwrite(valid.data(), 1, nq, out);
    const double med[2] = {median(t_motion), median(t_state)};
    std::fwrite(med, sizeof(double), 2, out);
    std::fclose(out);
    return 0;
}
