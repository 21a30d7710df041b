// The channels FoxgloveServer advertises and each client's subscriptions to them, internal to
// FoxgloveServer: the bookkeeping behind AddChannel, RemoveChannel, subscribe, unsubscribe, a
// client's departure and Publish. Not thread-safe: the server's mutex guards it.
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "client/station/foxglove_protocol.h"
#include "client/station/foxglove_server.h"

namespace stevi::station::internal {

struct Client;  // a WebSocket connection (foxglove_server_impl.h); only its address is used here

// Subscription changes to tell the listener about, in order: (channel, subscribed).
using SubscriptionChanges = std::vector<std::pair<uint32_t, bool>>;

struct Channel {
  ChannelSpec spec;
  Json advert;                                            // the advertise entry
  std::vector<std::pair<Client*, uint32_t>> subscribers;  // (client, its subscription id)
};

class Channels {
 public:
  // Adds a channel; returns its id (1, 2, ...; never reused).
  uint32_t Add(ChannelSpec spec);
  // Removes the channel and ends its subscriptions (a change when it had subscribers). False when
  // the id is unknown.
  bool Remove(uint32_t channel, SubscriptionChanges& changes);

  const Channel* Find(uint32_t channel) const;  // nullptr when unknown
  bool HasSubscribers(uint32_t channel) const;
  bool empty() const { return channels_.empty(); }
  Json Adverts() const;  // every channel's advertise entry, by id

  // Subscribes `client` to `channel` under the client's subscription id `id`: "" when done, else
  // the problem (the id in use, an unknown channel, a channel the client is subscribed to).
  std::string Subscribe(Client& client, uint32_t id, uint32_t channel,
                        SubscriptionChanges& changes);
  // Ends the client's subscription `id`: "" when done, else the problem (an unknown id).
  std::string Unsubscribe(const Client& client, uint32_t id, SubscriptionChanges& changes);
  // Ends every subscription of a client that is leaving, by id, and forgets the client.
  void UnsubscribeAll(const Client& client, SubscriptionChanges& changes);

 private:
  using ClientSubscriptions = std::map<uint32_t, uint32_t>;  // subscription id -> channel id

  // Ends the subscription at `it`, one of `client`'s.
  void End(const Client& client, ClientSubscriptions& mine, ClientSubscriptions::iterator it,
           SubscriptionChanges& changes);

  std::map<uint32_t, Channel> channels_;
  uint32_t next_channel_ = 1;
  std::unordered_map<const Client*, ClientSubscriptions> subscriptions_;
};

}  // namespace stevi::station::internal
