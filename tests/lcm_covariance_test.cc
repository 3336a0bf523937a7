// Covariances over LCM (docs/lcm.md): command COVARIANCE on ARBOR_COMMAND (the ids in its path,
// its utime the request), answered by a covariance_t on ARBOR_COVARIANCE, in process over
// memq://; the ids' parsing and covariance_t's checked decoding.
#include <chrono>
#include <condition_variable>
#include <mutex>
#include <sstream>
#include <vector>

#include <gtest/gtest.h>

#include "lcm_test_support.h"

namespace arbor::serve {
namespace {

using testing::Collector;

// The covariance_t answers on the bus, by request number.
class Answers {
 public:
  Answers(lcm::LCM& lcm, const Channels& ch) : lcm_(lcm) {
    sub_ = lcm.subscribe(ch.covariance, &Answers::on, this);
    sub_->setQueueCapacity(0);
  }
  ~Answers() { lcm_.unsubscribe(sub_); }
  Answers(const Answers&) = delete;
  Answers& operator=(const Answers&) = delete;
  /// Waits (at most 60 s, a failure guard) for the answer to `request`.
  bool wait(std::int64_t request, covariance_t* out) {
    std::unique_lock<std::mutex> lock(mutex_);
    const bool found = cv_.wait_for(lock, std::chrono::seconds(60), [&] {
      for (const auto& a : answers_)
        if (a.request == request) return true;
      return false;
    });
    for (const auto& a : answers_)
      if (a.request == request) *out = a;
    return found;
  }

 private:
  void on(const lcm::ReceiveBuffer* rbuf, const std::string&) {
    covariance_t m;
    ASSERT_EQ(decodeMessage(rbuf->data, static_cast<int>(rbuf->data_size), &m),
              MessageProblem::kNone);
    std::lock_guard<std::mutex> lock(mutex_);
    answers_.push_back(m);
    cv_.notify_all();
  }
  lcm::LCM& lcm_;
  lcm::Subscription* sub_ = nullptr;
  std::mutex mutex_;
  std::condition_variable cv_;
  std::vector<covariance_t> answers_;
};

command_t covarianceCommand(std::int64_t request, const std::string& ids) {
  command_t c;
  c.utime = request;
  c.command = command_t::COVARIANCE;
  c.path = ids;
  return c;
}

template <class M>
void publishCommand(lcm::LCM& lcm, const Service& service, const M& c) {
  const auto bytes = encodeMessage(c);
  lcm.publish(service.channels().command, bytes.data(), static_cast<unsigned>(bytes.size()));
}

Eigen::MatrixXd matrixOf(const covariance_t& m) {
  Eigen::MatrixXd out(m.dim, m.dim);
  for (int r = 0; r < m.dim; ++r)
    for (int c = 0; c < m.dim; ++c) out(r, c) = m.matrix[r][c];
  return out;
}

TEST(LcmCovariance, AnswersEqualTheSmootherFedDirectly) {
  const PoseGraph2 graph = testing::manhattanGraph(60, 4, -1, 5);
  const std::vector<int> order = testing::replayOrder(graph);
  lcm::LCM lcm("memq://");
  ASSERT_TRUE(lcm.good());
  std::ostringstream log;
  ServeOptions options;
  options.refine_on_exit = false;
  options.log = &log;
  Service service(lcm, options);
  Collector collector(lcm, service.channels());
  Answers answers(lcm, service.channels());
  service.start();
  // In lockstep (one update per edge, as the reference is fed): each edge is applied before the
  // next is sent, so the service's tree is the reference's, bit for bit.
  OnlineSmoother2 reference;
  std::int64_t seq = 0;
  for (int e : order) {
    const auto bytes = testing::edgeBytes(graph, e, ++seq);
    lcm.publish(service.channels().edges, bytes.data(), static_cast<unsigned>(bytes.size()));
    command_t status;
    status.command = command_t::STATUS;
    publishCommand(lcm, service, status);
    ASSERT_TRUE(collector.waitStatus([&](const status_t& s) { return s.applied == seq; }, 60));
    // The reference takes the edge as the service does, decoded from the bytes sent.
    const EdgeDecoding d = decodeEdge(bytes.data(), static_cast<int>(bytes.size()));
    ASSERT_TRUE(d.ok()) << d.detail;
    const auto& edge = std::get<StreamEdge<SE2>>(d.edge);
    reference.addEdge(edge.from, edge.to, edge.z, edge.omega);
    reference.update();
  }
  publishCommand(lcm, service, covarianceCommand(1, "10"));
  publishCommand(lcm, service, covarianceCommand(2, "3 50"));
  publishCommand(lcm, service, covarianceCommand(3, "999"));
  publishCommand(lcm, service, covarianceCommand(4, "1 2 3"));
  covariance_t one, two, unknown, three;
  ASSERT_TRUE(answers.wait(1, &one));
  ASSERT_TRUE(answers.wait(2, &two));
  ASSERT_TRUE(answers.wait(3, &unknown));
  ASSERT_TRUE(answers.wait(4, &three));
  service.stop();

  EXPECT_EQ(one.error, "");
  ASSERT_EQ(one.dim, 3);
  EXPECT_EQ(one.ids, std::vector<std::int64_t>{10});
  EXPECT_EQ(one.update, static_cast<std::int64_t>(order.size()));
  EXPECT_EQ(matrixOf(one), Eigen::MatrixXd(reference.marginalCovariance(10)));
  EXPECT_EQ(two.error, "");
  ASSERT_EQ(two.dim, 6);
  EXPECT_EQ(matrixOf(two), Eigen::MatrixXd(reference.jointMarginalCovariance(3, 50)));
  EXPECT_EQ(unknown.dim, 0);
  EXPECT_NE(unknown.error.find("999"), std::string::npos) << unknown.error;
  EXPECT_EQ(three.dim, 0);
  EXPECT_EQ(three.num_ids, 0);
  EXPECT_EQ(three.error, "covariance needs 1 or 2 pose ids, not 3 ('1 2 3')");
}

TEST(LcmCovariance, BeforeAnyEdgeIsRefused) {
  lcm::LCM lcm("memq://");
  ASSERT_TRUE(lcm.good());
  std::ostringstream log;
  ServeOptions options;
  options.refine_on_exit = false;
  options.log = &log;
  Service service(lcm, options);
  Answers answers(lcm, service.channels());
  service.start();
  publishCommand(lcm, service, covarianceCommand(7, "0"));
  covariance_t m;
  ASSERT_TRUE(answers.wait(7, &m));
  service.stop();
  EXPECT_EQ(m.error, "no estimate yet");
  EXPECT_EQ(m.dim, 0);
}

TEST(LcmCovariance, IdsOfThePath) {
  EXPECT_EQ(covarianceIds("12"), std::vector<Key>{12});
  EXPECT_EQ(covarianceIds(" 3   50 "), (std::vector<Key>{3, 50}));
  for (const std::string bad : {"", "a", "1 x", "-1", "1.5", "1 2 3", "99999999999999999999"}) {
    EXPECT_THROW(covarianceIds(bad), std::invalid_argument) << bad;
  }
  try {
    covarianceIds("4 x");
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_STREQ(e.what(), "covariance: 'x' in '4 x' is not a pose id");
  }
}

TEST(LcmCovariance, AnswerDecodingChecksLengths) {
  covariance_t m;
  m.request = 3;
  m.num_ids = 1;
  m.ids = {4};
  m.update = 2;
  m.dim = 3;
  m.matrix.assign(3, std::vector<double>(3, 0.5));
  const auto bytes = encodeMessage(m);
  covariance_t out;
  ASSERT_EQ(decodeMessage(bytes.data(), static_cast<int>(bytes.size()), &out),
            MessageProblem::kNone);
  EXPECT_EQ(out.matrix, m.matrix);
  EXPECT_EQ(decodeMessage(bytes.data(), static_cast<int>(bytes.size()) - 9, &out),
            MessageProblem::kTruncated);
  std::vector<std::uint8_t> bad = bytes;
  bad[24] = 0xff;  // num_ids negative
  EXPECT_EQ(decodeMessage(bad.data(), static_cast<int>(bad.size()), &out),
            MessageProblem::kMalformed);
}

}  // namespace
}  // namespace arbor::serve
