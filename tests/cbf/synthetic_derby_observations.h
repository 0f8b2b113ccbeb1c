#pragma once
// Synthetic Demolition Derby observations for the per-car barrier's trainer tests and benchmark
// (tests/cbf/car_barrier_trainer_test.cc, bench/car_barrier_train_bench.cc): 52 values, goal
// offset and velocity, then 12 cars (relative position and velocity) sorted nearest first.
#include <Eigen/Core>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "secure/common/rng.h"
#include "secure/data/data.h"

namespace secure::test {

constexpr int kObs = 52;
constexpr int kCars = 12;

inline std::vector<std::string> ObsNames() {
  std::vector<std::string> names = {"gx", "gy", "vx", "vy"};
  for (int j = 0; j < kCars; ++j)
    for (const char* f : {"dx", "dy", "dvx", "dvy"}) names.push_back("c" + std::to_string(j) + f);
  return names;
}

// Synthetic Derby observations. Safe: every car farther than 0.2 (uniform in [-1.5, 1.5]^2, so
// some are out of the sensing radius). Near-dangerous: the nearest car within 0.14, the others
// farther than 0.2. Cars sorted nearest first.
inline data::StateSet Synthetic(bool near_dangerous, int n, std::uint64_t seed, double safe_min = 0.2) {
  Rng rng(seed);
  data::StateSet set{near_dangerous ? "synthetic near-dangerous" : "synthetic safe", ObsNames(),
                     Eigen::MatrixXf(kObs, n)};
  for (int i = 0; i < n; ++i) {
    for (int f = 0; f < 4; ++f) set.states(f, i) = static_cast<float>(rng.Uniform(-1, 1));
    std::vector<std::array<float, 4>> cars(kCars);
    for (int j = 0; j < kCars; ++j) {
      double x, y;
      if (near_dangerous && j == 0) {
        const double rho = rng.Uniform(0, 0.14), a = rng.Uniform(0, 2 * M_PI);
        x = rho * std::cos(a);
        y = rho * std::sin(a);
      } else {
        do {
          x = rng.Uniform(-1.5, 1.5);
          y = rng.Uniform(-1.5, 1.5);
        } while (std::hypot(x, y) <= safe_min);
      }
      cars[j] = {static_cast<float>(x), static_cast<float>(y),
                 static_cast<float>(rng.Uniform(-0.5, 0.5)),
                 static_cast<float>(rng.Uniform(-0.5, 0.5))};
    }
    std::sort(cars.begin(), cars.end(), [](const auto& a, const auto& b) {
      return a[0] * a[0] + a[1] * a[1] < b[0] * b[0] + b[1] * b[1];
    });
    for (int j = 0; j < kCars; ++j)
      for (int q = 0; q < 4; ++q) set.states(4 + 4 * j + q, i) = cars[j][q];
  }
  return set;
}

}  // namespace secure::test
