// vox::Status and vox::StatusOr<T>: how every fallible call in vox reports failure.
//
// A Status is a code plus a message that names the problem and, where there is
// one, the file. Libraries never throw across their boundary and never exit;
// only tools/ turn a Status into an exit code. Thread-compatible value types.
#ifndef VOX_CORE_UTIL_STATUS_H_
#define VOX_CORE_UTIL_STATUS_H_

#include <cassert>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <variant>

namespace vox {

enum class StatusCode {
  kOk = 0,
  kInvalidArgument,   // the caller's input is malformed (bad ray, bad JSON, bad flag)
  kNotFound,          // a file, grid or field is missing
  kIoError,           // the OS refused a read, write, mmap, rename or fsync
  kCorruption,        // a file's contents fail a check (magic, checksum, bounds)
  kUnsupported,       // well-formed input vox does not handle (grid type, format major)
  kResourceExhausted, // out of memory, disk full, budget too small
  kInternal,          // a bug in vox
  kUnavailable,       // not ready yet (a brick still being read): ask again later
};

std::string_view StatusCodeName(StatusCode code);

class [[nodiscard]] Status {
 public:
  Status() = default;
  Status(StatusCode code, std::string message) : code_(code), message_(std::move(message)) {}

  bool ok() const { return code_ == StatusCode::kOk; }
  StatusCode code() const { return code_; }
  const std::string& message() const { return message_; }
  // "Corruption: <message>", or "OK".
  std::string ToString() const;
  // Returns a copy whose message is prefixed with `context`: "context: message".
  Status WithContext(std::string_view context) const;

 private:
  StatusCode code_ = StatusCode::kOk;
  std::string message_;
};

inline Status OkStatus() { return Status(); }
inline Status InvalidArgumentError(std::string m) { return {StatusCode::kInvalidArgument, std::move(m)}; }
inline Status NotFoundError(std::string m) { return {StatusCode::kNotFound, std::move(m)}; }
inline Status IoError(std::string m) { return {StatusCode::kIoError, std::move(m)}; }
inline Status CorruptionError(std::string m) { return {StatusCode::kCorruption, std::move(m)}; }
inline Status UnsupportedError(std::string m) { return {StatusCode::kUnsupported, std::move(m)}; }
inline Status ResourceExhaustedError(std::string m) { return {StatusCode::kResourceExhausted, std::move(m)}; }
inline Status UnavailableError(std::string m) { return {StatusCode::kUnavailable, std::move(m)}; }
inline Status InternalError(std::string m) { return {StatusCode::kInternal, std::move(m)}; }

// Either a T or a non-OK Status.
template <typename T>
class [[nodiscard]] StatusOr {
 public:
  StatusOr(const Status& status) : v_(status) { assert(!status.ok()); }  // NOLINT: implicit
  StatusOr(Status&& status) : v_(std::move(status)) { assert(!std::get<Status>(v_).ok()); }  // NOLINT
  StatusOr(const T& value) : v_(value) {}  // NOLINT
  StatusOr(T&& value) : v_(std::move(value)) {}  // NOLINT
  template <typename U>
    requires(std::is_constructible_v<T, U&&> && !std::is_same_v<std::decay_t<U>, Status> &&
             !std::is_same_v<std::decay_t<U>, T> && !std::is_same_v<std::decay_t<U>, StatusOr>)
  StatusOr(U&& value) : v_(T(std::forward<U>(value))) {}  // NOLINT

  bool ok() const { return std::holds_alternative<T>(v_); }
  Status status() const { return ok() ? OkStatus() : std::get<Status>(v_); }
  // REQUIRES: ok().
  T& value() & { assert(ok()); return std::get<T>(v_); }
  const T& value() const& { assert(ok()); return std::get<T>(v_); }
  T&& value() && { assert(ok()); return std::get<T>(std::move(v_)); }
  T& operator*() & { return value(); }
  const T& operator*() const& { return value(); }
  T* operator->() { return &value(); }
  const T* operator->() const { return &value(); }

 private:
  std::variant<Status, T> v_;
};

}  // namespace vox

#define VOX_CONCAT_INNER_(a, b) a##b
#define VOX_CONCAT_(a, b) VOX_CONCAT_INNER_(a, b)

// Returns the Status of `expr` from the enclosing function when it is not OK.
#define VOX_RETURN_IF_ERROR(expr)                      \
  do {                                                 \
    ::vox::Status vox_status_ = (expr);                \
    if (!vox_status_.ok()) return vox_status_;         \
  } while (0)

// `lhs = value of expr`, or returns its Status from the enclosing function.
#define VOX_ASSIGN_OR_RETURN(lhs, expr) \
  VOX_ASSIGN_OR_RETURN_IMPL_(VOX_CONCAT_(vox_statusor_, __LINE__), lhs, expr)
#define VOX_ASSIGN_OR_RETURN_IMPL_(tmp, lhs, expr) \
  auto tmp = (expr);                               \
  if (!tmp.ok()) return tmp.status();              \
  lhs = std::move(tmp).value()

#ifdef NDEBUG
#define VOX_DCHECK(cond) ((void)0)
#else
#define VOX_DCHECK(cond) assert(cond)
#endif

#endif  // VOX_CORE_UTIL_STATUS_H_
