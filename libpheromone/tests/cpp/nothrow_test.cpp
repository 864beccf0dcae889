// pheromone.hpp built with -fno-exceptions (libpheromone/tests/c_abi.sh):
//   nothrow_test FIELD X Y EXPECTED MISSING_FIELD
// only the status-returning calls exist: attach (a missing field is
// PHEROMONE_STATUS_NO_FIELD), wait, borrow, sample (the value at (X, Y) equals EXPECTED, probe's),
// one live borrow per Field (a second borrow and a wait while a Frame lives are
// PHEROMONE_STATUS_BORROWED), and a Frame that outlives its Field.
#include <chrono>
#include <cstdio>
#include <cstdlib>

#include "pheromone.hpp"

#if PHEROMONE_HPP_EXCEPTIONS
#error "build nothrow_test with -fno-exceptions"
#endif

namespace {
int failures = 0;
void check(bool ok, const char* what, PheromoneStatus s) {
  if (!ok) {
    std::fprintf(stderr, "nothrow_test: %s: %s: %s\n", what, pheromone::status_name(s),
                 pheromone_last_error());
    ++failures;
  }
}
}  // namespace

int main(int argc, char** argv) {
  if (argc != 6) {
    std::fprintf(stderr, "usage: nothrow_test FIELD X Y EXPECTED MISSING_FIELD\n");
    return 2;
  }
  const float x = std::strtof(argv[2], nullptr), y = std::strtof(argv[3], nullptr);
  const float expected = std::strtof(argv[4], nullptr);
  PheromoneAttachOptions o = pheromone::default_options();
  pheromone::Field missing;
  PheromoneStatus s = pheromone::Field::attach(argv[5], o, missing);
  check(s == PHEROMONE_STATUS_NO_FIELD && !missing, "a missing field", s);

  o.attach_timeout_ns = 5'000'000'000ull;
  o.deposits = 0;
  pheromone::Frame survivor;
  {
    pheromone::Field field;
    s = pheromone::Field::attach(argv[1], o, field);
    check(s == PHEROMONE_STATUS_OK && field, "attach", s);
    if (s != PHEROMONE_STATUS_OK) return 1;
    s = field.try_wait_frame(std::chrono::milliseconds(500));
    check(s == PHEROMONE_STATUS_OK || s == PHEROMONE_STATUS_TIMEOUT, "wait", s);
    pheromone::Frame frame;
    s = field.try_borrow(frame);
    check(s == PHEROMONE_STATUS_OK && frame, "borrow", s);
    float v = 0.0f;
    s = frame.try_value(0, x, y, v);
    check(s == PHEROMONE_STATUS_OK && v == expected, "the value equals probe's", s);
    pheromone::Frame second;
    s = field.try_borrow(second);
    check(s == PHEROMONE_STATUS_BORROWED && !second, "a second borrow", s);
    s = field.try_wait_frame(std::chrono::milliseconds(1));
    check(s == PHEROMONE_STATUS_BORROWED, "a wait while a Frame lives", s);
    survivor = std::move(frame);
  }
  float v = 0.0f;
  s = survivor.try_value(0, x, y, v);
  check(s == PHEROMONE_STATUS_OK && v == expected, "a Frame that outlived its Field", s);
  if (failures == 0) std::printf("nothrow: value %.9g equals probe's\n", v);
  return failures == 0 ? 0 : 1;
}
