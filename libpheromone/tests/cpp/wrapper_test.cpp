// pheromone.hpp against a live field (libpheromone/tests/c_abi.sh):
//   wrapper_test FIELD X Y EXPECTED MISSING_FIELD
// reads the value at (X, Y) zero-copy and checks it equals EXPECTED (pheromone probe's, parsed
// as a float), checks a missing field throws PHEROMONE_STATUS_NO_FIELD, deposits seed 000's
// ellipse at (X + 0.5, Y) and waits until the frame shows it.
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <type_traits>

#include "pheromone.hpp"

// A Frame and a Field are move-only: a copy is refused at compile time.
static_assert(!std::is_copy_constructible<pheromone::Frame>::value, "Frame is move-only");
static_assert(!std::is_copy_assignable<pheromone::Frame>::value, "Frame is move-only");
static_assert(std::is_nothrow_move_constructible<pheromone::Frame>::value, "Frame moves");
static_assert(!std::is_copy_constructible<pheromone::Field>::value, "Field is move-only");

namespace {
int failures = 0;
void check(bool ok, const std::string& what) {
  if (!ok) {
    std::fprintf(stderr, "wrapper_test: %s\n", what.c_str());
    ++failures;
  }
}
}  // namespace

int main(int argc, char** argv) {
  if (argc != 6) {
    std::fprintf(stderr, "usage: wrapper_test FIELD X Y EXPECTED MISSING_FIELD\n");
    return 2;
  }
  const float x = std::strtof(argv[2], nullptr), y = std::strtof(argv[3], nullptr);
  const float expected = std::strtof(argv[4], nullptr);
  try {
    pheromone::Field missing(argv[5]);
    check(false, "attaching a missing field did not throw");
  } catch (const pheromone::Error& e) {
    check(e.status() == PHEROMONE_STATUS_NO_FIELD, std::string("missing field: ") + e.what());
  }
  try {
    PheromoneAttachOptions o = pheromone::default_options();
    o.attach_timeout_ns = 5'000'000'000ull;
    pheromone::Field field(argv[1], o);
    field.wait_frame(std::chrono::seconds(2));
    float before = 0.0f;
    {
      pheromone::Frame frame = field.borrow();
      pheromone::Span<const float> plane = frame.plane(0);
      check(plane.size() == size_t(frame.width()) * frame.height(), "plane size");
      float value = frame.value(0, x, y);
      check(value == expected, "value " + std::to_string(value) + " != probe's " + argv[4]);
      before = frame.value(0, x + 0.5f, y);
      std::vector<float> sectors = frame.sectors(0, PheromonePose{x, y, 0.0f}, 1.0f, 2);
      check(sectors.size() == 5, "five sectors");
      try {
        field.wait_frame(std::chrono::milliseconds(1));
        check(false, "waiting while a frame is borrowed did not throw");
      } catch (const pheromone::Error& e) {
        check(e.status() == PHEROMONE_STATUS_BORROWED, e.what());
      }
      // One live borrow per Field: a second borrow, or `frame = field.borrow()` over a live
      // Frame, is refused while the first lives.
      try {
        pheromone::Frame second = field.borrow();
        check(false, "a second borrow while a Frame lives did not throw");
      } catch (const pheromone::Error& e) {
        check(e.status() == PHEROMONE_STATUS_BORROWED, e.what());
      }
      try {
        frame = field.borrow();
        check(false, "frame = field.borrow() over a live Frame did not throw");
      } catch (const pheromone::Error& e) {
        check(e.status() == PHEROMONE_STATUS_BORROWED, e.what());
      }
      pheromone::Frame other;
      check(field.try_borrow(other) == PHEROMONE_STATUS_BORROWED && !other,
            "try_borrow while a Frame lives");
      check(frame.value(0, x, y) == expected, "the first Frame still reads its frame");
      pheromone::Frame moved = std::move(frame);
      check(!frame && moved && moved.value(0, x, y) == expected, "a moved Frame");
    }  // the frame is released here
    {
      pheromone::Frame again = field.borrow();
      check(bool(again), "a borrow after the release");
    }
    // A Frame that outlives its Field keeps the handle (detached with the Frame: valgrind
    // sees no leak) and still reads its frame.
    {
      pheromone::Frame survivor;
      {
        PheromoneAttachOptions o2 = pheromone::default_options();
        o2.attach_timeout_ns = 5'000'000'000ull;
        o2.deposits = 0;
        pheromone::Field second(argv[1], o2);
        // Attached is not yet received: a borrow needs the first frame this Field took.
        check(second.wait_frame(std::chrono::seconds(5)), "a frame for the second Field");
        survivor = second.borrow();
      }
      float v = 0.0f;
      check(survivor.try_value(0, x, y, v) == PHEROMONE_STATUS_OK && v == expected,
            "a Frame that outlived its Field");
    }
    PheromonePoseEstimate pose{double(x) + 0.5, double(y), 0.0,
                               {0.02, 0.0, 0.0, 0.0, 0.02, 0.0, 0.0, 0.0, 0.1}};
    field.deposit_pose(pose);
    float after = before;
    for (int i = 0; i < 500 && after <= before; ++i) {
      if (!field.wait_frame(std::chrono::seconds(5))) break;
      after = field.borrow().value(0, x + 0.5f, y);
    }
    check(after > before, "the deposit never showed: " + std::to_string(after));
    PheromoneDeposit d{};
    d.kernel = PHEROMONE_KERNEL_ELLIPSE;
    d.x_m = x + 0.5f;
    d.y_m = y;
    d.amount = 0.01f;
    d.cov_xx = 0.02f;
    d.cov_yy = 0.02f;
    d.range_m = 1.0f;
    d.gamma_max = 100.0f;
    PheromoneReceipt r = field.deposit_confirmed(d, std::chrono::seconds(10));
    check(r.status == PHEROMONE_RECEIPT_APPLIED && r.sequence > 0, "confirmed deposit receipt");
    d.x_m = 1000.0f;
    try {
      field.deposit_confirmed(d, std::chrono::seconds(10));
      check(false, "a deposit outside the grid was not refused");
    } catch (const pheromone::Error& e) {
      check(e.status() == PHEROMONE_STATUS_REJECTED, e.what());
    }
    std::printf("wrapper: value %.9g equals probe's, deposit %.9g -> %.9g\n", expected, before,
                after);
  } catch (const pheromone::Error& e) {
    std::fprintf(stderr, "wrapper_test: %s\n", e.what());
    return 1;
  }
  return failures == 0 ? 0 : 1;
}
