#pragma once
// Synthetic Demolition Derby observations for the per-car barrier's tests and benchmarks
// (tests/cbf/car_barrier_trainer_test.cc, tests/cbf/car_barrier_test.cc,
// bench/car_barrier_train_bench.cc, bench/car_barrier_bench.cc): 52 values, goal offset and
// velocity, then 12 cars (relative position and velocity) sorted nearest first.
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

using SyntheticCar = std::array<float, 4>;  // dx, dy, dvx, dvy relative to the ego

// One observation into `observation` (kObs values): the goal offset and ego velocity uniform in
// [-1, 1) from `rng`, then the cars draw_car(0), ..., draw_car(kCars - 1) (drawn in that order)
// sorted nearest first.
template <typename DrawCar>
void WriteSyntheticObservation(Rng& rng, DrawCar&& draw_car,
                               Eigen::Ref<Eigen::VectorXf> observation) {
  for (int f = 0; f < 4; ++f) observation[f] = static_cast<float>(rng.Uniform(-1, 1));
  std::vector<SyntheticCar> cars(kCars);
  for (int j = 0; j < kCars; ++j) cars[j] = draw_car(j);
  std::sort(cars.begin(), cars.end(), [](const SyntheticCar& a, const SyntheticCar& b) {
    return a[0] * a[0] + a[1] * a[1] < b[0] * b[0] + b[1] * b[1];
  });
  for (int j = 0; j < kCars; ++j)
    for (int q = 0; q < 4; ++q) observation[4 + 4 * j + q] = cars[j][q];
}

// Synthetic Derby observations. Safe: every car farther than 0.2 (uniform in [-1.5, 1.5]^2, so
// some are out of the sensing radius). Near-dangerous: the nearest car within 0.14, the others
// farther than 0.2. Cars sorted nearest first.
inline data::StateSet Synthetic(bool near_dangerous, int n, std::uint64_t seed, double safe_min = 0.2) {
  Rng rng(seed);
  data::StateSet set{near_dangerous ? "synthetic near-dangerous" : "synthetic safe", ObsNames(),
                     Eigen::MatrixXf(kObs, n)};
  for (int i = 0; i < n; ++i) {
    const auto draw_car = [&](int j) -> SyntheticCar {
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
      return {static_cast<float>(x), static_cast<float>(y),
              static_cast<float>(rng.Uniform(-0.5, 0.5)),
              static_cast<float>(rng.Uniform(-0.5, 0.5))};
    };
    WriteSyntheticObservation(rng, draw_car, set.states.col(i));
  }
  return set;
}

}  // namespace secure::test
