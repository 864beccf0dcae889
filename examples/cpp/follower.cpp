// libpheromone from C++: seed 000's gradient follower loop on pheromone.hpp.
//
//   cmake -S examples/cpp -B build -DCMAKE_PREFIX_PATH=<prefix of libpheromone/install.sh>
//   cmake --build build && ./build/follower demo X Y [STEPS]
//
// A robot starting at (X, Y) steers up ∇P (seed 000 eqs. 15-16, read from each new frame with
// Rust's numbers, zero-copy) at the Table 2 speed for the level it senses, integrating its own
// unicycle pose between frames (no world process). It stops where the gradient vanishes or the
// trail is below the rejection level, and prints a line per step.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "pheromone.hpp"

namespace {

// Seed 000 Table 2: sensed 0-15 -> 0.15 m/s, 15-30 -> 0.45, 30-60 -> 0.65, 60+ -> 1.0.
double table2_speed(float level) {
  if (level >= 60.0f) return 1.0;
  if (level >= 30.0f) return 0.65;
  if (level >= 15.0f) return 0.45;
  return 0.15;
}

constexpr float kRejectLevel = 1e-3f;     // below this the trail is not followed
constexpr float kMinGradient = 1e-4f;     // per metre
constexpr double kMaxTurnRadPerS = 2.0;   // the robot's turn-rate limit

}  // namespace

int main(int argc, char** argv) {
  if (argc < 4) {
    std::fprintf(stderr, "usage: follower FIELD X Y [STEPS]\n");
    return 2;
  }
  try {
    PheromoneAttachOptions options = pheromone::default_options();
    options.attach_timeout_ns = 5'000'000'000ull;
    options.deposits = 0;
    pheromone::Field field(argv[1], options);
    double x = std::atof(argv[2]), y = std::atof(argv[3]), theta = 0.0;
    int steps = argc > 4 ? std::atoi(argv[4]) : 100;
    double last_time_s = -1.0;
    for (int step = 0; step < steps; ++step) {
      if (!field.wait_frame(std::chrono::seconds(2),
                            pheromone::Wait::spin(std::chrono::microseconds(200)))) {
        std::fprintf(stderr, "follower: no frame within 2 s\n");
        return 1;
      }
      pheromone::Frame frame = field.borrow();
      float level = frame.value(0, float(x), float(y));
      auto [gx, gy] = frame.gradient(0, float(x), float(y));
      double dt = last_time_s < 0.0 ? frame.view().dt_s : frame.sim_time_s() - last_time_s;
      last_time_s = frame.sim_time_s();
      double norm = std::hypot(gx, gy);
      if (level < kRejectLevel || norm < kMinGradient) {
        std::printf("step %d: stop at (%.3f, %.3f), level %g, |grad| %g\n", step, x, y, level, norm);
        return 0;
      }
      double want = std::atan2(gy, gx);
      double turn = std::remainder(want - theta, 2.0 * M_PI);
      double max_turn = kMaxTurnRadPerS * dt;
      theta += std::fmax(-max_turn, std::fmin(max_turn, turn));
      double v = table2_speed(level);
      x += v * dt * std::cos(theta);
      y += v * dt * std::sin(theta);
      std::printf("step %d (frame %llu): level %g, v %.2f m/s, pose (%.3f, %.3f, %.2f)\n", step,
                  static_cast<unsigned long long>(frame.sequence()), level, v, x, y, theta);
    }
    return 0;
  } catch (const pheromone::Error& e) {
    std::fprintf(stderr, "follower: %s\n", e.what());
    return 1;
  }
}
