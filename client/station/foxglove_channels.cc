// The channels and each client's subscriptions (foxglove_channels.h).
#include "client/station/foxglove_channels.h"

#include <algorithm>

namespace stevi::station::internal {

uint32_t Channels::Add(ChannelSpec spec) {
  const uint32_t id = next_channel_++;
  Channel& channel = channels_[id];
  channel.advert = ChannelAdvert(id, spec);
  channel.spec = std::move(spec);
  return id;
}

bool Channels::Remove(uint32_t channel, SubscriptionChanges& changes) {
  auto it = channels_.find(channel);
  if (it == channels_.end()) return false;
  for (const auto& [client, subscription] : it->second.subscribers) {
    auto mine = subscriptions_.find(client);
    if (mine != subscriptions_.end()) mine->second.erase(subscription);
  }
  if (!it->second.subscribers.empty()) changes.emplace_back(channel, false);
  channels_.erase(it);
  return true;
}

const Channel* Channels::Find(uint32_t channel) const {
  auto it = channels_.find(channel);
  return it != channels_.end() ? &it->second : nullptr;
}

bool Channels::HasSubscribers(uint32_t channel) const {
  const Channel* found = Find(channel);
  return found != nullptr && !found->subscribers.empty();
}

Json Channels::Adverts() const {
  Json adverts = Json::array();
  for (const auto& [id, channel] : channels_) adverts.push_back(channel.advert);
  return adverts;
}

std::string Channels::Subscribe(Client& client, uint32_t id, uint32_t channel,
                                SubscriptionChanges& changes) {
  auto mine = subscriptions_.find(&client);
  if (mine != subscriptions_.end() && mine->second.contains(id)) {
    return "subscription id " + std::to_string(id) + " is already in use";
  }
  auto it = channels_.find(channel);
  if (it == channels_.end()) return "unknown channel " + std::to_string(channel);
  auto& subscribers = it->second.subscribers;
  if (std::any_of(subscribers.begin(), subscribers.end(),
                  [&](const auto& s) { return s.first == &client; })) {
    return "already subscribed to channel " + std::to_string(channel);
  }
  if (subscribers.empty()) changes.emplace_back(channel, true);
  subscribers.emplace_back(&client, id);
  subscriptions_[&client][id] = channel;
  return "";
}

std::string Channels::Unsubscribe(const Client& client, uint32_t id, SubscriptionChanges& changes) {
  auto mine = subscriptions_.find(&client);
  if (mine == subscriptions_.end()) return "unknown subscription id " + std::to_string(id);
  auto it = mine->second.find(id);
  if (it == mine->second.end()) return "unknown subscription id " + std::to_string(id);
  End(client, mine->second, it, changes);
  return "";
}

void Channels::UnsubscribeAll(const Client& client, SubscriptionChanges& changes) {
  auto mine = subscriptions_.find(&client);
  if (mine == subscriptions_.end()) return;
  while (!mine->second.empty()) End(client, mine->second, mine->second.begin(), changes);
  subscriptions_.erase(mine);
}

void Channels::End(const Client& client, ClientSubscriptions& mine,
                   ClientSubscriptions::iterator it, SubscriptionChanges& changes) {
  const uint32_t subscription = it->first;
  auto channel = channels_.find(it->second);
  if (channel != channels_.end()) {
    auto& subscribers = channel->second.subscribers;
    std::erase_if(subscribers,
                  [&](const auto& s) { return s.first == &client && s.second == subscription; });
    if (subscribers.empty()) changes.emplace_back(channel->first, false);
  }
  mine.erase(it);
}

}  // namespace stevi::station::internal
