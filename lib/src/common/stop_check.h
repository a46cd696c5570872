// StopCheck: how a long kernel of `common` asks whether its caller wants it to stop (Ctrl-C)
// without knowing who decides; core's InterruptPoll (core/interrupt_poll.h) is one.
#pragma once

namespace avsplat {

class StopCheck {
public:
    /// True when the work should stop; the caller then reports why (e.g. throws Interrupted).
    virtual bool should_stop() noexcept = 0;

protected:
    ~StopCheck() = default;
};

}  // namespace avsplat
