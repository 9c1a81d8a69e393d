// notify_peer.cc: C++ suppliers and consumers of a CosNotification channel, written as Miro's
// C++ services use one (Miro::StructuredPushSupplier and Miro::StructuredPushConsumer, and
// Miro::Client's naming layout), built with g++ against omniORB, its CosNotify stubs (libCOS4)
// and omniidl's stubs of the project's Miro IDL. tests/test_corba_notify.py and
// bench/bench_notify.py run it.
//
// The channel is found as Miro's services find it: the naming context named by -MNC (made when
// missing, `bind_new_context`, else resolved), then `EventChannel` in it, narrowed to
// CosNotifyChannelAdmin::EventChannel. A supplier makes an admin of its own (OR_OP), obtains a
// structured proxy push consumer, sets its offers (offer_change on the admin, then
// obtain_subscription_types), and connects; a consumer does the same with subscriptions.
//
//   notify_peer supply N [-MNC ctx] [ORB options]   offers ctx/Gps and ctx/Laser; prints what
//        is subscribed ("SUBSCRIBED ctx Gps 1"), "READY", then for each line on stdin pushes N
//        Miro::GpsDataIDL (type Gps) and N Miro::RangeScanEventIDL (type Laser), numbered on
//        from the last, and prints "SENT total"; subscription changes ("CHANGE + d t") are
//        printed as they come; it ends when stdin closes
//   notify_peer consume N d/t... [-MNC ctx]        subscribes to d/t... (`*` any); prints
//        "OFFERED d t" for each type offered, "CONNECTED", then "EVENT d t ..." for each of N
//        events (or until stdin closes), "OFFER + d t" for offer changes
//   notify_peer subscriptions [-MNC ctx]           prints the channel's subscription types
//        ("TYPE d t") as a supplier sees them, then "END"
//   notify_peer bench-supply N SIZE [RATE] [-MNC ctx]   after "READY" and a line on stdin,
//        pushes N NotifyBench::Sample (domain ctx, type Sample, SIZE bytes of CDR) as fast as
//        the channel takes them (or RATE a second); "SENT N SECONDS"; ends when stdin closes
//   notify_peer bench-consume N [-MNC ctx]         receives ctx/Sample; after N events (or 3 s
//        without any) prints "GOT COUNT SECONDS P50_US" (from its first event to its last)

#include <CosNotifyChannelAdmin.hh>
#include <CosNotifyComm.hh>
#include <omniORB4/Naming.hh>
#include <Gps.hh>
#include <RangeEvent.hh>
#include <NotifyBench.hh>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <iostream>
#include <mutex>
#include <string>
#include <vector>

static std::mutex out_mutex;

static void say(const std::string& line)
{
  std::lock_guard<std::mutex> guard(out_mutex);
  std::cout << line << std::endl;
}

static long long now_ns()
{
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch()).count();
}

static CosNotification::EventTypeSeq types(const std::vector<std::pair<std::string, std::string>>& v)
{
  CosNotification::EventTypeSeq seq;
  seq.length(v.size());
  for (CORBA::ULong i = 0; i < v.size(); ++i) {
    seq[i].domain_name = CORBA::string_dup(v[i].first.c_str());
    seq[i].type_name = CORBA::string_dup(v[i].second.c_str());
  }
  return seq;
}

static CosNotification::EventTypeSeq asterisk()
{
  return types({{"*", "*"}});
}

static bool same(const CosNotification::EventType& a, const CosNotification::EventType& b)
{
  return std::strcmp(a.domain_name, b.domain_name) == 0 && std::strcmp(a.type_name, b.type_name) == 0;
}

// ---- as Miro::Client does it -------------------------------------------------------------------

static CosNotifyChannelAdmin::EventChannel_ptr resolve_channel(CORBA::ORB_ptr orb, const std::string& context)
{
  CORBA::Object_var obj = orb->resolve_initial_references("NameService");
  CosNaming::NamingContext_var initial = CosNaming::NamingContext::_narrow(obj);
  CosNaming::Name n;
  n.length(1);
  n[0].id = CORBA::string_dup(context.c_str());
  CosNaming::NamingContext_var naming;
  try {
    naming = initial->bind_new_context(n);
  }
  catch (const CosNaming::NamingContext::AlreadyBound&) {
    CORBA::Object_var found = initial->resolve(n);
    naming = CosNaming::NamingContext::_narrow(found);
  }
  n[0].id = CORBA::string_dup("EventChannel");
  CORBA::Object_var ch = naming->resolve(n);
  return CosNotifyChannelAdmin::EventChannel::_narrow(ch);
}

// ---- as Miro::StructuredPushSupplier is --------------------------------------------------------

class Supplier : public POA_CosNotifyComm::StructuredPushSupplier
{
public:
  Supplier(CosNotifyChannelAdmin::EventChannel_ptr ec, const CosNotification::EventTypeSeq& offers)
    : ec_(CosNotifyChannelAdmin::EventChannel::_duplicate(ec)), offers_(asterisk()), subscribed_(1, false)
  {
    admin_ = ec_->new_for_suppliers(CosNotifyChannelAdmin::OR_OP, adminId_);
    CosNotifyChannelAdmin::ProxyConsumer_var proxy =
      admin_->obtain_notification_push_consumer(CosNotifyChannelAdmin::STRUCTURED_EVENT, proxyId_);
    proxy_ = CosNotifyChannelAdmin::StructuredProxyPushConsumer::_narrow(proxy);
    setOffers(offers);
    objref_ = _this();
    proxy_->connect_structured_push_supplier(objref_);
    connected_ = true;
  }

  void disconnect()
  {
    if (connected_) {
      connected_ = false;
      proxy_->disconnect_structured_push_consumer();
      admin_->destroy();
    }
  }

  // The offers replace the last ones: the admin is told what was added and removed, then the
  // channel's subscriptions are looked up for them.
  void setOffers(const CosNotification::EventTypeSeq& offers)
  {
    std::lock_guard<std::mutex> guard(mutex_);
    CosNotification::EventTypeSeq added, removed;
    for (CORBA::ULong i = 0; i < offers.length(); ++i) {
      bool known = false;
      for (CORBA::ULong j = 0; j < offers_.length(); ++j) known = known || same(offers[i], offers_[j]);
      if (!known) { added.length(added.length() + 1); added[added.length() - 1] = offers[i]; }
    }
    for (CORBA::ULong j = 0; j < offers_.length(); ++j) {
      bool kept = false;
      for (CORBA::ULong i = 0; i < offers.length(); ++i) kept = kept || same(offers[i], offers_[j]);
      if (!kept) { removed.length(removed.length() + 1); removed[removed.length() - 1] = offers_[j]; }
    }
    offers_ = offers;
    subscribed_.assign(offers_.length(), false);
    admin_->offer_change(added, removed);
    CosNotification::EventTypeSeq_var subs =
      proxy_->obtain_subscription_types(CosNotifyChannelAdmin::ALL_NOW_UPDATES_ON);
    for (CORBA::ULong i = 0; i < offers_.length(); ++i)
      for (CORBA::ULong j = 0; j < subs->length(); ++j)
        if (matches(subs[j], offers_[i])) subscribed_[i] = true;
  }

  bool subscribed(const std::string& domain, const std::string& type)
  {
    std::lock_guard<std::mutex> guard(mutex_);
    for (CORBA::ULong i = 0; i < offers_.length(); ++i)
      if (domain == (const char*)offers_[i].domain_name && type == (const char*)offers_[i].type_name)
        return subscribed_[i];
    return false;
  }

  void sendEvent(const CosNotification::StructuredEvent& event)
  {
    if (connected_) proxy_->push_structured_event(event);
  }

  void subscription_change(const CosNotification::EventTypeSeq& added,
                           const CosNotification::EventTypeSeq& removed)
  {
    std::lock_guard<std::mutex> guard(mutex_);
    for (CORBA::ULong i = 0; i < added.length(); ++i) {
      say(std::string("CHANGE + ") + (const char*)added[i].domain_name + " " + (const char*)added[i].type_name);
      for (CORBA::ULong j = 0; j < offers_.length(); ++j)
        if (matches(added[i], offers_[j])) subscribed_[j] = true;
    }
    for (CORBA::ULong i = 0; i < removed.length(); ++i)
      say(std::string("CHANGE - ") + (const char*)removed[i].domain_name + " " + (const char*)removed[i].type_name);
  }

  void disconnect_structured_push_supplier() { connected_ = false; }

  static bool matches(const CosNotification::EventType& sub, const CosNotification::EventType& offer)
  {
    bool d = std::strcmp(sub.domain_name, "*") == 0 || std::strcmp(sub.domain_name, offer.domain_name) == 0;
    bool t = std::strcmp(sub.type_name, "*") == 0 || std::strcmp(sub.type_name, offer.type_name) == 0;
    return d && t;
  }

private:
  CosNotifyChannelAdmin::EventChannel_var ec_;
  CosNotifyChannelAdmin::AdminID adminId_;
  CosNotifyChannelAdmin::SupplierAdmin_var admin_;
  CosNotifyChannelAdmin::ProxyID proxyId_;
  CosNotifyChannelAdmin::StructuredProxyPushConsumer_var proxy_;
  CosNotifyComm::StructuredPushSupplier_var objref_;
  CosNotification::EventTypeSeq offers_;
  std::vector<bool> subscribed_;
  std::mutex mutex_;
  bool connected_ = false;
};

// ---- as Miro::StructuredPushConsumer is --------------------------------------------------------

class Consumer : public POA_CosNotifyComm::StructuredPushConsumer
{
public:
  Consumer(CosNotifyChannelAdmin::EventChannel_ptr ec, const CosNotification::EventTypeSeq& subscriptions)
    : ec_(CosNotifyChannelAdmin::EventChannel::_duplicate(ec)), subscriptions_(asterisk())
  {
    admin_ = ec_->new_for_consumers(CosNotifyChannelAdmin::OR_OP, adminId_);
    CosNotifyChannelAdmin::ProxySupplier_var proxy =
      admin_->obtain_notification_push_supplier(CosNotifyChannelAdmin::STRUCTURED_EVENT, proxyId_);
    proxy_ = CosNotifyChannelAdmin::StructuredProxyPushSupplier::_narrow(proxy);
    setSubscriptions(subscriptions);
  }

  void connect()
  {
    objref_ = _this();
    proxy_->connect_structured_push_consumer(objref_);
    connected_ = true;
    CosNotification::EventTypeSeq_var offered =
      proxy_->obtain_offered_types(CosNotifyChannelAdmin::ALL_NOW_UPDATES_ON);
    for (CORBA::ULong i = 0; i < offered->length(); ++i)
      say(std::string("OFFERED ") + (const char*)offered[i].domain_name + " " + (const char*)offered[i].type_name);
  }

  void disconnect()
  {
    if (connected_) {
      connected_ = false;
      try {
        proxy_->disconnect_structured_push_supplier();
        admin_->destroy();
      }
      catch (const CORBA::Exception&) {
      }
    }
  }

  void setSubscriptions(const CosNotification::EventTypeSeq& subs)
  {
    CosNotification::EventTypeSeq added, removed;
    for (CORBA::ULong i = 0; i < subs.length(); ++i) {
      bool known = false;
      for (CORBA::ULong j = 0; j < subscriptions_.length(); ++j) known = known || same(subs[i], subscriptions_[j]);
      if (!known) { added.length(added.length() + 1); added[added.length() - 1] = subs[i]; }
    }
    for (CORBA::ULong j = 0; j < subscriptions_.length(); ++j) {
      bool kept = false;
      for (CORBA::ULong i = 0; i < subs.length(); ++i) kept = kept || same(subs[i], subscriptions_[j]);
      if (!kept) { removed.length(removed.length() + 1); removed[removed.length() - 1] = subscriptions_[j]; }
    }
    subscriptions_ = subs;
    admin_->subscription_change(added, removed);
  }

  void offer_change(const CosNotification::EventTypeSeq& added, const CosNotification::EventTypeSeq& removed)
  {
    for (CORBA::ULong i = 0; i < added.length(); ++i)
      say(std::string("OFFER + ") + (const char*)added[i].domain_name + " " + (const char*)added[i].type_name);
    for (CORBA::ULong i = 0; i < removed.length(); ++i)
      say(std::string("OFFER - ") + (const char*)removed[i].domain_name + " " + (const char*)removed[i].type_name);
  }

  void disconnect_structured_push_consumer() { connected_ = false; }

  virtual void push_structured_event(const CosNotification::StructuredEvent& event) = 0;

protected:
  CosNotifyChannelAdmin::EventChannel_var ec_;
  CosNotifyChannelAdmin::AdminID adminId_;
  CosNotifyChannelAdmin::ConsumerAdmin_var admin_;
  CosNotifyChannelAdmin::ProxyID proxyId_;
  CosNotifyChannelAdmin::StructuredProxyPushSupplier_var proxy_;
  CosNotifyComm::StructuredPushConsumer_var objref_;
  CosNotification::EventTypeSeq subscriptions_;
  bool connected_ = false;
};

// ---- the modes ---------------------------------------------------------------------------------

static CosNotification::StructuredEvent event_of(const std::string& domain, const std::string& type)
{
  CosNotification::StructuredEvent e;
  e.header.fixed_header.event_type.domain_name = CORBA::string_dup(domain.c_str());
  e.header.fixed_header.event_type.type_name = CORBA::string_dup(type.c_str());
  e.header.fixed_header.event_name = CORBA::string_dup("");
  return e;
}

static void burst(Supplier* supplier, const std::string& ctx, int from, int n);

static int supply(CORBA::ORB_ptr orb, const std::string& ctx, int n)
{
  CosNotifyChannelAdmin::EventChannel_var ec = resolve_channel(orb, ctx);
  Supplier* supplier = new Supplier(ec, types({{ctx, "Gps"}, {ctx, "Laser"}}));
  say(std::string("SUBSCRIBED ") + ctx + " Gps " + (supplier->subscribed(ctx, "Gps") ? "1" : "0"));
  say(std::string("SUBSCRIBED ") + ctx + " Laser " + (supplier->subscribed(ctx, "Laser") ? "1" : "0"));
  say("READY");
  std::string line;
  int sent = 0;
  while (std::getline(std::cin, line)) {
    burst(supplier, ctx, sent, n);
    sent += n;
    say("SENT " + std::to_string(2 * sent));
  }
  supplier->disconnect();
  return 0;
}

static void burst(Supplier* supplier, const std::string& ctx, int from, int n)
{
  for (int i = from; i < from + n; ++i) {
    Miro::GpsDataIDL gps;
    gps.time.sec = 1000 + i;
    gps.time.usec = 500;
    gps.utcTime.sec = 2000 + i;
    gps.utcTime.usec = 0;
    gps.valid = i % 2 == 0;
    gps.quality = Miro::GPS_FIX_DGPS;
    gps.mode = Miro::GPS_MODE_3D;
    gps.latitude = 48.0 + i * 0.001;
    gps.longitude = 9.0 + i * 0.001;
    gps.altitude = 500.25 + i;
    gps.geoidSeparation = 47.5f;
    gps.satellitesUsed = 7;
    gps.satellites.length(2);
    gps.satellites[0] = i;
    gps.satellites[1] = i + 1;
    gps.hdop = 0.9f;
    gps.vdop = 1.1f;
    gps.pdop = 1.4f;
    gps.speed = 1.5f;
    gps.course = 90.0f;
    gps.magneticVariation = 2.0f;
    gps.dgpsAge = 3.0f;
    gps.dgpsStation = 42;
    CosNotification::StructuredEvent e = event_of(ctx, "Gps");
    e.remainder_of_body <<= gps;
    supplier->sendEvent(e);

    Miro::RangeScanEventIDL scan;
    scan.time.sec = 3000 + i;
    scan.time.usec = 7;
    scan.range.length(2);
    scan.range[0].length(3);
    for (CORBA::ULong k = 0; k < 3; ++k) scan.range[0][k] = i * 10 + k;
    scan.range[1].length(1);
    scan.range[1][0] = -1;
    CosNotification::StructuredEvent l = event_of(ctx, "Laser");
    l.remainder_of_body <<= scan;
    supplier->sendEvent(l);
  }
}

class Printer : public Consumer
{
public:
  Printer(CosNotifyChannelAdmin::EventChannel_ptr ec, const CosNotification::EventTypeSeq& subs, int n)
    : Consumer(ec, subs), left_(n) {}

  void push_structured_event(const CosNotification::StructuredEvent& e)
  {
    std::string head = std::string("EVENT ") + (const char*)e.header.fixed_header.event_type.domain_name +
                       " " + (const char*)e.header.fixed_header.event_type.type_name;
    const Miro::GpsDataIDL* gps;
    const Miro::RangeScanEventIDL* scan;
    char text[256];
    if (e.remainder_of_body >>= gps) {
      std::snprintf(text, sizeof text, " gps %d %.6f %.6f %.2f %u sats %u", (int)gps->time.sec,
                    gps->latitude, gps->longitude, gps->altitude, (unsigned)gps->satellitesUsed,
                    (unsigned)gps->satellites.length());
      say(head + text);
    }
    else if (e.remainder_of_body >>= scan) {
      std::string ranges;
      for (CORBA::ULong g = 0; g < scan->range.length(); ++g) {
        ranges += g ? "|" : "";
        for (CORBA::ULong k = 0; k < scan->range[g].length(); ++k)
          ranges += (k ? "," : "") + std::to_string(scan->range[g][k]);
      }
      say(head + " scan " + std::to_string(scan->time.sec) + " " + ranges);
    }
    else {
      CORBA::TypeCode_var tc = e.remainder_of_body.type();
      say(head + " other " + std::to_string(tc->kind()));
    }
    if (--left_ == 0) say("DONE");
  }

  int left_;
};

static int consume(CORBA::ORB_ptr orb, const std::string& ctx, int n, const std::vector<std::string>& wanted)
{
  CosNotifyChannelAdmin::EventChannel_var ec = resolve_channel(orb, ctx);
  std::vector<std::pair<std::string, std::string>> v;
  for (const std::string& w : wanted) {
    size_t slash = w.find('/');
    v.push_back({w.substr(0, slash), w.substr(slash + 1)});
  }
  Printer* printer = new Printer(ec, types(v), n);
  printer->connect();
  say("CONNECTED");
  std::string line;
  while (std::getline(std::cin, line)) {
  }
  printer->disconnect();
  return 0;
}

static int subscriptions(CORBA::ORB_ptr orb, const std::string& ctx)
{
  CosNotifyChannelAdmin::EventChannel_var ec = resolve_channel(orb, ctx);
  CosNotifyChannelAdmin::AdminID id;
  CosNotifyChannelAdmin::SupplierAdmin_var admin = ec->new_for_suppliers(CosNotifyChannelAdmin::OR_OP, id);
  CosNotifyChannelAdmin::ProxyID pid;
  CosNotifyChannelAdmin::ProxyConsumer_var proxy =
    admin->obtain_notification_push_consumer(CosNotifyChannelAdmin::STRUCTURED_EVENT, pid);
  CosNotification::EventTypeSeq_var subs = proxy->obtain_subscription_types(CosNotifyChannelAdmin::ALL_NOW_UPDATES_OFF);
  for (CORBA::ULong i = 0; i < subs->length(); ++i)
    say(std::string("TYPE ") + (const char*)subs[i].domain_name + " " + (const char*)subs[i].type_name);
  say("END");
  admin->destroy();
  return 0;
}

static int bench_supply(CORBA::ORB_ptr orb, const std::string& ctx, int n, int size, int rate)
{
  CosNotifyChannelAdmin::EventChannel_var ec = resolve_channel(orb, ctx);
  Supplier* supplier = new Supplier(ec, types({{ctx, "Sample"}}));
  say("READY");
  std::string line;
  if (!std::getline(std::cin, line)) return 1;
  NotifyBench::Sample s;
  int pad = size - 16 > 0 ? size - 16 : 0;  // sent_ns, seq, the sequence's length
  s.pad.length(pad);
  for (int k = 0; k < pad; ++k) s.pad[k] = (CORBA::Octet)k;
  CosNotification::StructuredEvent e = event_of(ctx, "Sample");
  auto t0 = std::chrono::steady_clock::now();
  for (int i = 0; i < n; ++i) {
    if (rate > 0) {  // paced: event i leaves at i / rate seconds
      auto due = t0 + std::chrono::nanoseconds((long long)i * 1000000000LL / rate);
      while (std::chrono::steady_clock::now() < due) omni_thread::yield();
    }
    s.sent_ns = now_ns();
    s.seq = i;
    e.remainder_of_body <<= s;
    supplier->sendEvent(e);
  }
  double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  char text[64];
  std::snprintf(text, sizeof text, "SENT %d %.6f", n, secs);
  say(text);
  while (std::getline(std::cin, line)) {
  }
  supplier->disconnect();
  return 0;
}

class Counter : public Consumer
{
public:
  Counter(CosNotifyChannelAdmin::EventChannel_ptr ec, const CosNotification::EventTypeSeq& subs, int n)
    : Consumer(ec, subs), wanted_(n) { latencies_.reserve(n); }

  void push_structured_event(const CosNotification::StructuredEvent& e)
  {
    const NotifyBench::Sample* s;
    if (!(e.remainder_of_body >>= s)) return;
    long long now = now_ns();
    std::lock_guard<std::mutex> guard(mutex_);
    if (latencies_.empty()) first_ = std::chrono::steady_clock::now();
    last_ = std::chrono::steady_clock::now();
    latencies_.push_back((now - s->sent_ns) / 1000.0);
  }

  bool finished(std::chrono::steady_clock::time_point now)
  {
    std::lock_guard<std::mutex> guard(mutex_);
    if ((int)latencies_.size() >= wanted_) return true;
    return !latencies_.empty() && now - last_ > std::chrono::seconds(3);
  }

  void report()
  {
    std::lock_guard<std::mutex> guard(mutex_);
    std::vector<double> l = latencies_;
    std::sort(l.begin(), l.end());
    double secs = l.empty() ? 0 : std::chrono::duration<double>(last_ - first_).count();
    char text[128];
    std::snprintf(text, sizeof text, "GOT %zu %.6f %.1f", l.size(), secs, l.empty() ? 0.0 : l[l.size() / 2]);
    say(text);
  }

private:
  int wanted_;
  std::vector<double> latencies_;
  std::chrono::steady_clock::time_point first_, last_;
  std::mutex mutex_;
};

static int bench_consume(CORBA::ORB_ptr orb, const std::string& ctx, int n)
{
  CosNotifyChannelAdmin::EventChannel_var ec = resolve_channel(orb, ctx);
  Counter* counter = new Counter(ec, types({{ctx, "Sample"}}), n);
  counter->connect();
  say("CONNECTED");
  while (!counter->finished(std::chrono::steady_clock::now())) omni_thread::sleep(0, 20000000);
  counter->report();
  counter->disconnect();
  return 0;
}

int main(int argc, char** argv)
{
  try {
    CORBA::ORB_var orb = CORBA::ORB_init(argc, argv);
    std::string ctx = "robot1";
    std::vector<std::string> args;
    for (int i = 1; i < argc; ++i) {
      if ((std::strcmp(argv[i], "-MNC") == 0 || std::strcmp(argv[i], "-MiroNamingContext") == 0) && i + 1 < argc)
        ctx = argv[++i];
      else
        args.push_back(argv[i]);
    }
    if (args.empty()) {
      std::cerr << "usage: notify_peer supply|consume|subscriptions|bench-supply|bench-consume ..." << std::endl;
      return 2;
    }
    CORBA::Object_var obj = orb->resolve_initial_references("RootPOA");
    PortableServer::POA_var poa = PortableServer::POA::_narrow(obj);
    PortableServer::POAManager_var manager = poa->the_POAManager();
    manager->activate();
    const std::string& mode = args[0];
    int n = args.size() > 1 ? std::atoi(args[1].c_str()) : 0;
    int rc = 2;
    if (mode == "supply") rc = supply(orb, ctx, n);
    else if (mode == "consume")
      rc = consume(orb, ctx, n, std::vector<std::string>(args.begin() + 2, args.end()));
    else if (mode == "subscriptions") rc = subscriptions(orb, ctx);
    else if (mode == "bench-supply")
      rc = bench_supply(orb, ctx, n, args.size() > 2 ? std::atoi(args[2].c_str()) : 100,
                        args.size() > 3 ? std::atoi(args[3].c_str()) : 0);
    else if (mode == "bench-consume") rc = bench_consume(orb, ctx, n);
    orb->destroy();
    return rc;
  }
  catch (CORBA::SystemException& e) {
    say(std::string("FAIL CORBA::") + e._name() + " minor " + std::to_string(e.minor()));
  }
  catch (CORBA::Exception& e) {
    say(std::string("FAIL CORBA::") + e._name());
  }
  return 1;
}
