#include "avsplat/core/interrupt.h"

#include "core/interrupt_poll.h"

namespace avsplat {

namespace detail {
thread_local const InterruptCheck* current_interrupt_check = nullptr;
}  // namespace detail

ScopedInterruptCheck::ScopedInterruptCheck(std::function<bool()> check, std::chrono::nanoseconds interval)
    : installed_{std::move(check), interval}, previous_(detail::current_interrupt_check) {
    detail::current_interrupt_check = installed_.check ? &installed_ : nullptr;
}

ScopedInterruptCheck::~ScopedInterruptCheck() { detail::current_interrupt_check = previous_; }

void throw_if_interrupted() {
    const InterruptCheck* installed = detail::current_interrupt_check;
    if (installed && InterruptPoll::run(installed->check)) throw Interrupted();
}

}  // namespace avsplat
