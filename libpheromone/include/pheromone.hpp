// pheromone.hpp: a header-only C++17 wrapper of pheromone.h (libpheromone). See docs/c-abi.md.
//
// - pheromone::Field owns a handle (attach in the constructor, detach in the destructor);
// - pheromone::Frame is a borrowed frame (released in its destructor); its planes are
//   pheromone::Span<const float> (std::span in C++20) into shared memory, no copy;
// - a failed call throws pheromone::Error (status + the library's message). A wait that times
//   out is not an error: Field::wait_frame returns false. Exceptions rather than an
//   expected-style result because C++17 has no std::expected, ROS 2's rclcpp reports errors by
//   exceptions too, and every error here is either a setup error (no field, other layout) or
//   bad input, not a value of the hot path, which costs nothing while nothing throws.
//
// Thread safety: as pheromone.h — a Field (and its Frame) is used by one thread at a time.
// A Frame must not outlive its Field.
#ifndef PHEROMONE_HPP
#define PHEROMONE_HPP

#include <chrono>
#include <cstddef>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "pheromone.h"

#if __cplusplus >= 202002L && __has_include(<span>)
#include <span>
#endif

namespace pheromone {

#if __cplusplus >= 202002L && __has_include(<span>) && defined(__cpp_lib_span)
template <class T>
using Span = std::span<T>;
#else
/// A minimal std::span (C++17): a pointer and a length, no ownership.
template <class T>
class Span {
 public:
  constexpr Span() noexcept = default;
  constexpr Span(T* data, std::size_t size) noexcept : data_(data), size_(size) {}
  constexpr T* data() const noexcept { return data_; }
  constexpr std::size_t size() const noexcept { return size_; }
  constexpr bool empty() const noexcept { return size_ == 0; }
  constexpr T& operator[](std::size_t i) const noexcept { return data_[i]; }
  constexpr T* begin() const noexcept { return data_; }
  constexpr T* end() const noexcept { return data_ + size_; }

 private:
  T* data_ = nullptr;
  std::size_t size_ = 0;
};
#endif

/// The name of a status, e.g. "PHEROMONE_STATUS_NO_FIELD".
inline const char* status_name(PheromoneStatus s) noexcept {
  switch (s) {
    case PHEROMONE_STATUS_OK: return "PHEROMONE_STATUS_OK";
    case PHEROMONE_STATUS_TIMEOUT: return "PHEROMONE_STATUS_TIMEOUT";
    case PHEROMONE_STATUS_NO_FIELD: return "PHEROMONE_STATUS_NO_FIELD";
    case PHEROMONE_STATUS_BAD_ARGUMENT: return "PHEROMONE_STATUS_BAD_ARGUMENT";
    case PHEROMONE_STATUS_LAYOUT: return "PHEROMONE_STATUS_LAYOUT";
    case PHEROMONE_STATUS_NO_FRAME: return "PHEROMONE_STATUS_NO_FRAME";
    case PHEROMONE_STATUS_BORROWED: return "PHEROMONE_STATUS_BORROWED";
    case PHEROMONE_STATUS_NOT_DELIVERED: return "PHEROMONE_STATUS_NOT_DELIVERED";
    case PHEROMONE_STATUS_SHM_ERROR: return "PHEROMONE_STATUS_SHM_ERROR";
    case PHEROMONE_STATUS_INTERNAL: return "PHEROMONE_STATUS_INTERNAL";
    case PHEROMONE_STATUS_REJECTED: return "PHEROMONE_STATUS_REJECTED";
  }
  return "PHEROMONE_STATUS_?";
}

/// A failed call: its status and the library's message.
class Error : public std::runtime_error {
 public:
  Error(PheromoneStatus status, const char* message)
      : std::runtime_error(std::string(status_name(status)) + ": " + message), status_(status) {}
  PheromoneStatus status() const noexcept { return status_; }

 private:
  PheromoneStatus status_;
};

/// Throws `Error` unless `s` is OK.
inline void check(PheromoneStatus s) {
  if (s != PHEROMONE_STATUS_OK) throw Error(s, pheromone_last_error());
}

/// How Field::wait_frame waits.
struct Wait {
  static PheromoneWaitPolicy event() noexcept { return {PHEROMONE_WAIT_EVENT, 0}; }
  static PheromoneWaitPolicy spin(std::chrono::nanoseconds spin) noexcept {
    return {PHEROMONE_WAIT_SPIN, static_cast<uint64_t>(spin.count())};
  }
  static PheromoneWaitPolicy busy_poll() noexcept { return {PHEROMONE_WAIT_BUSY_POLL, 0}; }
};

/// The attach options' defaults (this header's layout version, deposits on).
inline PheromoneAttachOptions default_options() {
  PheromoneAttachOptions o;
  check(pheromone_attach_options_init(&o));
  return o;
}

/// The Rust depositor's defaults for seed 000's ellipse deposit.
inline PheromoneEllipseParams default_ellipse_params() {
  PheromoneEllipseParams p;
  check(pheromone_ellipse_params_init(&p));
  return p;
}

class Field;

/// A borrowed frame: valid (not freed, not overwritten) until destroyed. Move-only.
class Frame {
 public:
  Frame(Frame&& o) noexcept : field_(std::exchange(o.field_, nullptr)), view_(o.view_) {}
  Frame& operator=(Frame&& o) noexcept {
    if (this != &o) {
      release();
      field_ = std::exchange(o.field_, nullptr);
      view_ = o.view_;
    }
    return *this;
  }
  Frame(const Frame&) = delete;
  Frame& operator=(const Frame&) = delete;
  ~Frame() { release(); }

  const PheromoneFrameView& view() const noexcept { return view_; }
  uint64_t sequence() const noexcept { return view_.sequence; }
  uint64_t stamp_ns() const noexcept { return view_.stamp_ns; }
  double sim_time_s() const noexcept { return view_.sim_time_s; }
  uint32_t channels() const noexcept { return view_.channels; }
  uint32_t width() const noexcept { return view_.width; }
  uint32_t height() const noexcept { return view_.height; }
  float cell_size_m() const noexcept { return view_.cell_size_m; }

  /// Channel `c`'s cells in shared memory, row-major from the lower-left cell.
  Span<const float> plane(uint32_t c) const {
    if (c >= view_.channels) check_channel(c);
    return Span<const float>(view_.planes[c], view_.plane_len);
  }

  /// Rust's FrameView::value.
  float value(uint32_t channel, float x_m, float y_m) const {
    float v = 0.0f;
    check(pheromone_sample_value(handle(), channel, x_m, y_m, &v));
    return v;
  }

  /// Rust's FrameView::gradient: (∂P/∂x, ∂P/∂y) per metre.
  std::pair<float, float> gradient(uint32_t channel, float x_m, float y_m) const {
    std::pair<float, float> g{0.0f, 0.0f};
    check(pheromone_sample_gradient(handle(), channel, x_m, y_m, &g.first, &g.second));
    return g;
  }

  /// Rust's FrameView::antennas: (left, right).
  std::pair<float, float> antennas(uint32_t channel, PheromonePose pose, float wheel_base_m) const {
    std::pair<float, float> a{0.0f, 0.0f};
    check(pheromone_sample_antennas(handle(), channel, pose, wheel_base_m, &a.first, &a.second));
    return a;
  }

  /// Rust's FrameView::sector_means into `out` (size ≥ 2·half_sectors + 1), no allocation.
  void sectors(uint32_t channel, PheromonePose pose, float radius_m, uint32_t half_sectors,
               Span<float> out) const {
    check(pheromone_sample_sectors(handle(), channel, pose, radius_m, half_sectors, out.data(),
                                   out.size()));
  }

  /// As above, into a new vector.
  std::vector<float> sectors(uint32_t channel, PheromonePose pose, float radius_m,
                             uint32_t half_sectors) const {
    std::vector<float> out(2 * static_cast<std::size_t>(half_sectors) + 1);
    sectors(channel, pose, radius_m, half_sectors, Span<float>(out.data(), out.size()));
    return out;
  }

 private:
  friend class Field;
  Frame(PheromoneField* field, const PheromoneFrameView& view) : field_(field), view_(view) {}
  const PheromoneField* handle() const {
    if (field_ == nullptr) throw Error(PHEROMONE_STATUS_NO_FRAME, "this Frame was moved from");
    return field_;
  }
  void check_channel(uint32_t c) const {
    throw Error(PHEROMONE_STATUS_BAD_ARGUMENT,
                ("channel = " + std::to_string(c) + ": the frame has " +
                 std::to_string(view_.channels) + " channel(s)")
                    .c_str());
  }
  void release() noexcept {
    if (field_ != nullptr) pheromone_frame_release(std::exchange(field_, nullptr));
  }

  PheromoneField* field_;
  PheromoneFrameView view_;
};

/// An attachment to a running field. Move-only; detaches when destroyed.
class Field {
 public:
  /// Attaches to field `name` (throws Error: PHEROMONE_STATUS_NO_FIELD, _LAYOUT, …).
  explicit Field(const std::string& name, const PheromoneAttachOptions& options = default_options()) {
    check(pheromone_field_attach(name.c_str(), &options, &handle_));
  }
  Field(Field&& o) noexcept : handle_(std::exchange(o.handle_, nullptr)) {}
  Field& operator=(Field&& o) noexcept {
    if (this != &o) {
      pheromone_field_detach(handle_);
      handle_ = std::exchange(o.handle_, nullptr);
    }
    return *this;
  }
  Field(const Field&) = delete;
  Field& operator=(const Field&) = delete;
  ~Field() { pheromone_field_detach(handle_); }

  /// Waits up to `timeout` for a newer frame; false if none came.
  bool wait_frame(std::chrono::nanoseconds timeout,
                  PheromoneWaitPolicy policy = Wait::event()) {
    PheromoneStatus s =
        pheromone_wait_frame(handle_, policy, static_cast<uint64_t>(timeout.count()));
    if (s == PHEROMONE_STATUS_TIMEOUT) return false;
    check(s);
    return true;
  }

  /// Borrows the newest frame until the returned Frame is destroyed.
  Frame borrow() {
    PheromoneFrameView view;
    check(pheromone_frame_borrow(handle_, &view));
    return Frame(handle_, view);
  }

  void deposit(const PheromoneDeposit& d) { check(pheromone_deposit(handle_, &d)); }

  /// Sends a deposit and waits up to `timeout` for the field's receipt (applied in frame N, or
  /// forwarded by a mirror). Throws `Error` with PHEROMONE_STATUS_REJECTED when the field refused
  /// it, and PHEROMONE_STATUS_TIMEOUT when no receipt came (it may still be applied, once).
  PheromoneReceipt deposit_confirmed(const PheromoneDeposit& d, std::chrono::nanoseconds timeout) {
    PheromoneReceipt r{};
    check(pheromone_deposit_confirmed(handle_, &d, static_cast<uint64_t>(timeout.count()), &r));
    return r;
  }

  /// Seed 000's uncertainty-aware ellipse deposit for a pose estimate.
  void deposit_pose(const PheromonePoseEstimate& pose,
                    const PheromoneEllipseParams& params = default_ellipse_params()) {
    check(pheromone_deposit_pose(handle_, &pose, &params));
  }

  PheromoneField* get() const noexcept { return handle_; }

 private:
  PheromoneField* handle_ = nullptr;
};

}  // namespace pheromone

#endif  // PHEROMONE_HPP
