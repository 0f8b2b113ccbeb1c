// The machine's single-core FP32 reference figures, against which barrier_eval_bench's GFLOPS are
// read:
//   Sgemm/...        OpenBLAS cblas_sgemm, one thread (openblas_set_num_threads(1)).
//   EigenGemm/...    Eigen MatrixXf product, one thread (Eigen is built without OpenMP here).
//                    1024^3 is the large-GEMM reference; the other shapes are the layers of the
//                    barrier nets (W (out x in) times a batch of activations (in x N)).
//   FmaPeak          a register-only FMA loop: the core's arithmetic ceiling for the compiled ISA.
//   Activation/...   Eigen tanh / relu over a (64 x 4096) block: the per-element cost that the
//                    GFLOPS figure of a net does not count.
// Shapes are Args({M, K, N}) for C (M x N) = A (M x K) * B (K x N); GFLOPS counts 2*M*N*K.
// Without OpenBLAS (SECURE_HAVE_OPENBLAS undefined or 0) the Sgemm benchmarks are left out.

#include <benchmark/benchmark.h>

#include <Eigen/Core>
#include <string>

#if defined(__AVX2__) || defined(__AVX512F__)
#include <immintrin.h>
#endif

#if SECURE_HAVE_OPENBLAS
#include <cblas.h>  // OpenBLAS's (declares openblas_set_num_threads)
#endif

namespace {

void SetGemmCounters(benchmark::State& state, double m, double k, double n) {
  state.counters["GFLOPS"] =
      benchmark::Counter(2.0 * m * n * k * 1e-9, benchmark::Counter::kIsIterationInvariantRate,
                         benchmark::Counter::kIs1000);
}

#if SECURE_HAVE_OPENBLAS
void BM_Sgemm(benchmark::State& state) {
  openblas_set_num_threads(1);
  const int m = static_cast<int>(state.range(0)), k = static_cast<int>(state.range(1)),
            n = static_cast<int>(state.range(2));
  // Column-major, as Eigen's default storage.
  const Eigen::MatrixXf a = Eigen::MatrixXf::Random(m, k), b = Eigen::MatrixXf::Random(k, n);
  Eigen::MatrixXf c = Eigen::MatrixXf::Zero(m, n);
  auto run = [&] {
    cblas_sgemm(CblasColMajor, CblasNoTrans, CblasNoTrans, m, n, k, 1.0f, a.data(), m, b.data(), k,
                0.0f, c.data(), m);
  };
  run();  // warm up (and let OpenBLAS set up its buffers)
  for (auto _ : state) {
    run();
    benchmark::DoNotOptimize(c.data());
    benchmark::ClobberMemory();
  }
  SetGemmCounters(state, m, k, n);
  state.SetLabel(std::string("OpenBLAS ") + openblas_get_corename() + ", " +
                 std::to_string(openblas_get_num_threads()) + " thread");
}
BENCHMARK(BM_Sgemm)
    ->ArgNames({"M", "K", "N"})
    ->Args({1024, 1024, 1024})
    ->Args({256, 256, 128})
    ->Args({64, 64, 64})
    ->Args({64, 64, 4096})
    ->Args({256, 256, 4096});
#endif  // SECURE_HAVE_OPENBLAS

// "Eigen 3.4.0 AVX2+FMA": the version and the widest SIMD path Eigen compiled in.
std::string EigenDescription() {
  std::string simd =
#if defined(EIGEN_VECTORIZE_AVX512)
      "AVX-512";
#elif defined(EIGEN_VECTORIZE_AVX2)
      "AVX2";
#elif defined(EIGEN_VECTORIZE_AVX)
      "AVX";
#elif defined(EIGEN_VECTORIZE_SSE2)
      "SSE2";
#else
      "no SIMD";
#endif
#if defined(EIGEN_VECTORIZE_FMA)
  simd += "+FMA";
#endif
  return "Eigen " + std::to_string(EIGEN_WORLD_VERSION) + "." +
         std::to_string(EIGEN_MAJOR_VERSION) + "." + std::to_string(EIGEN_MINOR_VERSION) + " " +
         simd;
}

void BM_EigenGemm(benchmark::State& state) {
  Eigen::setNbThreads(1);  // a no-op unless built with OpenMP; explicit for the reader
  const Eigen::Index m = state.range(0), k = state.range(1), n = state.range(2);
  const Eigen::MatrixXf a = Eigen::MatrixXf::Random(m, k), b = Eigen::MatrixXf::Random(k, n);
  Eigen::MatrixXf c = Eigen::MatrixXf::Zero(m, n);
  c.noalias() = a * b;  // warm up
  for (auto _ : state) {
    c.noalias() = a * b;
    benchmark::DoNotOptimize(c.data());
    benchmark::ClobberMemory();
  }
  SetGemmCounters(state, m, k, n);
  state.SetLabel(EigenDescription());
}
BENCHMARK(BM_EigenGemm)
    ->ArgNames({"M", "K", "N"})
    ->Args({1024, 1024, 1024})
    ->Args({256, 256, 128})    // Panda hidden layer, batch 128
    ->Args({64, 64, 64})       // DI hidden layer, batch 64
    ->Args({64, 64, 4096})     // DI hidden layer, batch 4096
    ->Args({256, 256, 4096});  // Panda hidden layer, batch 4096

// Register-resident FMAs with enough independent accumulators to cover FMA latency x ports
// (e.g. 4 cycles x 2 ports on Zen 3 / Skylake needs >= 8); 12 leaves headroom.
void BM_FmaPeak(benchmark::State& state) {
#if defined(__AVX512F__)
  using Vec = __m512;
  constexpr int kLanes = 16;
  const char* isa = "AVX-512";
  auto set1 = [](float x) { return _mm512_set1_ps(x); };
  auto fma = [](Vec a, Vec b, Vec c) { return _mm512_fmadd_ps(a, b, c); };
  auto add = [](Vec a, Vec b) { return _mm512_add_ps(a, b); };
  auto sum = [](Vec a) { return _mm512_reduce_add_ps(a); };
#elif defined(__AVX2__) && defined(__FMA__)
  using Vec = __m256;
  constexpr int kLanes = 8;
  const char* isa = "AVX2+FMA";
  auto set1 = [](float x) { return _mm256_set1_ps(x); };
  auto fma = [](Vec a, Vec b, Vec c) { return _mm256_fmadd_ps(a, b, c); };
  auto add = [](Vec a, Vec b) { return _mm256_add_ps(a, b); };
  auto sum = [](Vec a) {
    alignas(32) float v[8];
    _mm256_store_ps(v, a);
    return v[0] + v[1] + v[2] + v[3] + v[4] + v[5] + v[6] + v[7];
  };
#else
  state.SkipWithError("FmaPeak needs AVX2+FMA or AVX-512 (build with -march=native)");
  for (auto _ : state) {
  }
  return;
#endif
#if defined(__AVX512F__) || (defined(__AVX2__) && defined(__FMA__))
  constexpr int kAcc = 12;
  constexpr long kInner = 4096;
  // x * 1 + tiny: stays finite and cannot be folded away (the values are opaque to the compiler).
  float one = 1.0f, tiny = 1e-7f;
  benchmark::DoNotOptimize(one);
  benchmark::DoNotOptimize(tiny);
  const Vec a = set1(one), b = set1(tiny);
  Vec acc[kAcc];
  for (int i = 0; i < kAcc; ++i) acc[i] = set1(static_cast<float>(i));
  for (auto _ : state) {
    for (long r = 0; r < kInner; ++r) {
      for (int i = 0; i < kAcc; ++i) acc[i] = fma(acc[i], a, b);
    }
    benchmark::DoNotOptimize(acc[0]);
  }
  Vec total = acc[0];
  for (int i = 1; i < kAcc; ++i) total = add(total, acc[i]);
  float result = sum(total);
  benchmark::DoNotOptimize(result);
  state.counters["GFLOPS"] = benchmark::Counter(2.0 * kLanes * kAcc * kInner * 1e-9,
                                                benchmark::Counter::kIsIterationInvariantRate,
                                                benchmark::Counter::kIs1000);
  state.SetLabel(std::string(isa) + ", " + std::to_string(kAcc) + " accumulators");
#endif
}
BENCHMARK(BM_FmaPeak);

// Elementwise activations over a (64 x 4096) block (a DI hidden layer at batch 4096), as
// InferenceMlp applies them; out of place so that every iteration sees the same inputs.
void BM_Activation(benchmark::State& state, bool tanh) {
  const Eigen::MatrixXf source = Eigen::MatrixXf::Random(64, 4096);
  Eigen::MatrixXf z(source.rows(), source.cols());
  for (auto _ : state) {
    if (tanh) {
      z.array() = source.array().tanh();
    } else {
      z = source.cwiseMax(0.0f);
    }
    benchmark::DoNotOptimize(z.data());
    benchmark::ClobberMemory();
  }
  const double elements = static_cast<double>(z.size());
  state.counters["ns_per_element"] = benchmark::Counter(
      elements * 1e-9, benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
  state.SetItemsProcessed(state.iterations() * z.size());
  state.SetLabel(EigenDescription());
}
BENCHMARK_CAPTURE(BM_Activation, tanh, true);
BENCHMARK_CAPTURE(BM_Activation, relu, false);

}  // namespace
