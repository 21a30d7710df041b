// The messages' field tables (the Fields of each struct in messages.h), checked against what does
// not come from them: the struct's own members, reached by structured bindings, and codec.h's
// message table (CRC_EXTRA and lengths from the XML). A table that misses a field, lists one twice
// or puts the base fields out of wire order fails here.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <tuple>
#include <type_traits>
#include <vector>

#include "client/mavlink/messages.h"
#include "tests/client/mavlink/round_trip.h"

namespace stevi::client::mavlink {
namespace {

using AllMessages =
    std::tuple<Heartbeat, SystemTime, GpsRawInt, Attitude, AttitudeQuaternion, GlobalPositionInt,
               CommandLong, CommandAck, AdsbVehicle, ObstacleDistance>;

// Converts to any member type, to count an aggregate's members.
struct AnyMember {
  template <class T>
  operator T() const;  // NOLINT(google-explicit-constructor): only in unevaluated contexts
};

template <class T, class... A>
constexpr std::size_t MemberCount() {
  if constexpr (requires { T{A{}..., AnyMember{}}; }) {
    return MemberCount<T, A..., AnyMember>();
  } else {
    return sizeof...(A);
  }
}

// The struct's data members as a tuple of references, in declaration order.
template <class T>
auto Members(T& m) {
  constexpr std::size_t n = MemberCount<T>();
  static_assert(n == 2 || n == 6 || n == 7 || n == 9 || n == 11 || n == 13 || n == 16,
                "add a binding for this member count");
  if constexpr (n == 2) {
    auto& [a, b] = m;
    return std::tie(a, b);
  } else if constexpr (n == 6) {
    auto& [a, b, c, d, e, f] = m;
    return std::tie(a, b, c, d, e, f);
  } else if constexpr (n == 7) {
    auto& [a, b, c, d, e, f, g] = m;
    return std::tie(a, b, c, d, e, f, g);
  } else if constexpr (n == 9) {
    auto& [a, b, c, d, e, f, g, h, i] = m;
    return std::tie(a, b, c, d, e, f, g, h, i);
  } else if constexpr (n == 11) {
    auto& [a, b, c, d, e, f, g, h, i, j, k] = m;
    return std::tie(a, b, c, d, e, f, g, h, i, j, k);
  } else if constexpr (n == 13) {
    auto& [a, b, c, d, e, f, g, h, i, j, k, l, o] = m;
    return std::tie(a, b, c, d, e, f, g, h, i, j, k, l, o);
  } else {
    auto& [a, b, c, d, e, f, g, h, i, j, k, l, o, p, q, r] = m;
    return std::tie(a, b, c, d, e, f, g, h, i, j, k, l, o, p, q, r);
  }
}

template <class T>
struct IsArray : std::false_type {};
template <class T, std::size_t N>
struct IsArray<std::array<T, N>> : std::true_type {};

// A distinct non-zero value for the k-th scalar: every byte of an integer is k; a float is k +
// 0.25.
template <class T>
T Distinct(int k) {
  if constexpr (std::is_floating_point_v<T>) {
    return static_cast<T>(k) + static_cast<T>(0.25);
  } else {
    using U = std::make_unsigned_t<T>;
    U bits = 0;
    for (std::size_t i = 0; i < sizeof(T); ++i) bits = static_cast<U>((bits << 8U) | U(k));
    return static_cast<T>(bits);
  }
}

// Sets every member (each array element too) to a distinct non-zero value; returns the size of
// the members' wire bytes.
template <class T>
std::size_t FillDistinct(T& m) {
  int k = 1;
  std::size_t size = 0;
  const auto set = [&k, &size](auto& member) {
    using M = std::decay_t<decltype(member)>;
    if constexpr (IsArray<M>::value) {
      for (auto& element : member) element = Distinct<std::decay_t<decltype(element)>>(k++);
    } else {
      member = Distinct<M>(k++);
    }
    size += sizeof(M);
  };
  std::apply([&set](auto&... member) { (set(member), ...); }, Members(m));
  return size;
}

template <class T>
void ExpectEveryFieldRoundTrips() {
  SCOPED_TRACE(FindMessage(T::kId)->name);
  T m;
  const std::size_t size = FillDistinct(m);
  EXPECT_NE(m, T{});
  const std::vector<uint8_t> payload = Pack(m);
  EXPECT_EQ(payload.size(), size);
  testing::ExpectRoundTrip(m, FindMessage(T::kId)->max_length);
}

// The wire type name the CRC_EXTRA takes for a member type.
template <class T>
std::string_view TypeName() {
  if constexpr (std::is_same_v<T, char>) return "char";
  if constexpr (std::is_same_v<T, float>) return "float";
  if constexpr (std::is_same_v<T, uint8_t>) return "uint8_t";
  if constexpr (std::is_same_v<T, int8_t>) return "int8_t";
  if constexpr (std::is_same_v<T, uint16_t>) return "uint16_t";
  if constexpr (std::is_same_v<T, int16_t>) return "int16_t";
  if constexpr (std::is_same_v<T, uint32_t>) return "uint32_t";
  if constexpr (std::is_same_v<T, int32_t>) return "int32_t";
  if constexpr (std::is_same_v<T, uint64_t>) return "uint64_t";
  if constexpr (std::is_same_v<T, int64_t>) return "int64_t";
  return "?";
}

// A visitor that adds up a table's lengths, checks the base fields' order and computes the
// CRC_EXTRA as the specification does: "NAME ", then per base field "type name " (and an array's
// length as a byte).
class Summary {
 public:
  explicit Summary(std::string_view message_name) {
    crc_ = Crc16(Bytes(std::string(message_name) + " "));
  }

  template <class T>
  void Field(const T& /*value*/, std::string_view name) {
    Add<T>(name, 0);
  }
  template <class T, std::size_t N>
  void Field(const std::array<T, N>& /*values*/, std::string_view name) {
    Add<T>(name, N);
  }
  void Extensions() { extensions_ = true; }

  std::size_t base_length = 0;
  std::size_t extension_length = 0;
  std::vector<std::string> out_of_order;  // base fields larger than the one before

  uint8_t CrcExtra() const { return static_cast<uint8_t>((crc_ & 0xFFU) ^ (crc_ >> 8U)); }

 private:
  static std::vector<uint8_t> Bytes(const std::string& text) { return {text.begin(), text.end()}; }

  template <class T>
  void Add(std::string_view name, std::size_t array_length) {
    const std::size_t length = sizeof(T) * std::max<std::size_t>(array_length, 1);
    if (extensions_) {
      extension_length += length;
      return;
    }
    if (sizeof(T) > last_size_) out_of_order.emplace_back(name);
    last_size_ = sizeof(T);
    base_length += length;
    crc_ = Crc16(Bytes(std::string(TypeName<T>()) + " " + std::string(name) + " "), crc_);
    if (array_length > 0) {
      const auto byte = static_cast<uint8_t>(array_length);
      crc_ = Crc16(std::span<const uint8_t>(&byte, 1), crc_);
    }
  }

  uint16_t crc_ = 0xFFFF;
  bool extensions_ = false;
  std::size_t last_size_ = 8;
};

template <class T>
void ExpectTableMatchesCodec() {
  const MessageInfo* info = FindMessage(T::kId);
  ASSERT_NE(info, nullptr) << T::kId;
  SCOPED_TRACE(info->name);
  Summary summary(info->name);
  const T m;
  T::Fields(m, summary);
  EXPECT_EQ(summary.base_length, std::size_t{info->min_length});
  EXPECT_EQ(summary.base_length + summary.extension_length, std::size_t{info->max_length});
  EXPECT_EQ(summary.out_of_order, std::vector<std::string>{});
  EXPECT_EQ(int{summary.CrcExtra()}, int{info->crc_extra});
}

template <class T>
void ExpectKnown() {
  EXPECT_NE(FindMessage(T::kId), nullptr) << T::kId;
}

TEST(FieldTables, EveryMessageIsListed) {
  ASSERT_EQ(std::tuple_size_v<AllMessages>, KnownMessages().size());
  std::apply([](auto... m) { (ExpectKnown<decltype(m)>(), ...); }, AllMessages{});
}

TEST(FieldTables, EveryFieldRoundTripsAndTakesItsBytes) {
  std::apply([](auto... m) { (ExpectEveryFieldRoundTrips<decltype(m)>(), ...); }, AllMessages{});
}

TEST(FieldTables, LengthsOrderAndCrcExtraMatchTheCodecTable) {
  std::apply([](auto... m) { (ExpectTableMatchesCodec<decltype(m)>(), ...); }, AllMessages{});
}

}  // namespace
}  // namespace stevi::client::mavlink
