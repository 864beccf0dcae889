// A C++ program keeps its own SIGTERM handling while it waits on a field (issue 47); run by
// libpheromone/tests/c_abi.sh, which sends the SIGTERMs from outside (the protocol of
// libpheromone/tests/c/signal_test.c):
//
//   signal_test_cpp FIELD WAITS
//
// Its handler is installed with SA_RESTART (as glibc's signal() does). Prints "ready"; then WAITS
// blocking event waits, alternately through Field::try_wait_frame (must return
// PHEROMONE_STATUS_INTERRUPTED) and Field::wait_frame (must throw pheromone::Error with that
// status), each with the handler run: "interrupted I"; a confirmed deposit waiting for its
// receipt, interrupted too: "interrupted deposit"; after the driver's end line on stdin, "seen K".
#include <signal.h>

#include <chrono>
#include <cstdlib>
#include <iostream>
#include <string>

#include "pheromone.hpp"

namespace {

volatile sig_atomic_t seen = 0;

extern "C" void on_term(int) { seen = seen + 1; }

int fail(const std::string& what) {
  std::cerr << what << "\n";
  return 1;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 3) return fail("usage: signal_test_cpp FIELD WAITS");
  const int waits = std::atoi(argv[2]);
  struct sigaction sa {};
  sa.sa_handler = on_term;
  sigemptyset(&sa.sa_mask);
  sa.sa_flags = SA_RESTART;
  if (sigaction(SIGTERM, &sa, nullptr) != 0) return fail("sigaction failed");
  try {
    PheromoneAttachOptions o = pheromone::default_options();
    o.attach_timeout_ns = 10'000'000'000ull;
    pheromone::Field field(argv[1], o);
    // The field's current frame (its history): held before the waits, each for a newer one.
    {
      pheromone::Frame current;
      PheromoneStatus s = field.try_borrow(current);
      if (s == PHEROMONE_STATUS_NO_FRAME && !field.wait_frame(std::chrono::seconds(10))) {
        return fail("no current frame within 10 s");
      }
    }
    std::cout << "ready" << std::endl;
    for (int i = 1; i <= waits; i++) {
      const sig_atomic_t at_start = seen;
      PheromoneStatus s = PHEROMONE_STATUS_OK;
      if (i % 2 == 1) {
        s = field.try_wait_frame(std::chrono::seconds(60));
      } else {
        try {
          field.wait_frame(std::chrono::seconds(60));
        } catch (const pheromone::Error& e) {
          s = e.status();
        }
      }
      if (s != PHEROMONE_STATUS_INTERRUPTED) {
        return fail("wait " + std::to_string(i) + ": " + pheromone::status_name(s) +
                    ", expected PHEROMONE_STATUS_INTERRUPTED");
      }
      if (seen == at_start) return fail("wait interrupted, but the handler did not run");
      std::cout << "interrupted " << i << std::endl;
    }
    PheromoneDeposit d{};
    d.kernel = PHEROMONE_KERNEL_ELLIPSE;
    d.amount = 0.01f;
    d.cov_xx = 0.04f;
    d.cov_yy = 0.04f;
    d.range_m = 0.5f;
    d.gamma_max = 100.0f;
    const sig_atomic_t at_start = seen;
    try {
      field.deposit_confirmed(d, std::chrono::seconds(60));
      return fail("the confirmed deposit returned a receipt; expected an interruption");
    } catch (const pheromone::Error& e) {
      if (e.status() != PHEROMONE_STATUS_INTERRUPTED) return fail(e.what());
    }
    if (seen == at_start) return fail("deposit interrupted, but the handler did not run");
    std::cout << "interrupted deposit" << std::endl;
    std::string line;
    if (!std::getline(std::cin, line)) return fail("stdin closed before the driver's end line");
  } catch (const pheromone::Error& e) {
    return fail(e.what());
  }
  std::cout << "seen " << static_cast<int>(seen) << std::endl;
  return 0;
}
