"""Object references through generated stubs: stubs, local servants, nil, `Object`, sequences
of references, references of the wrong kind."""

from __future__ import annotations

from types import SimpleNamespace

import pytest
from stub_support import CountingInvoker

from miro_gen.exceptions import (
    BAD_PARAM,
)
from miro_gen.runtime.rpc import Stub

# =============================================================================================
# object references
# =============================================================================================


def test_pass_a_stub(gen: SimpleNamespace, inv: CountingInvoker) -> None:
    Rpc, Node = gen.Rpc, gen.impl.Node
    a_servant, b_servant = Node("a"), Node("b")
    a, b = inv.stub(Rpc.Node, a_servant), inv.stub(Rpc.Node, b_servant)
    assert a.set_next(b) is None
    (received,) = a_servant.received
    assert type(received) is Rpc.Node  # arrives as a stub, not as the servant
    assert received == b and received._ref == b._ref
    assert received.name() == "b"
    got = a.next()
    assert type(got) is Rpc.Node and got == b
    assert got.name() == "b"


def test_pass_a_local_servant(gen: SimpleNamespace, inv: CountingInvoker) -> None:
    Rpc, Node = gen.Rpc, gen.impl.Node
    a_servant, c_servant = Node("a"), Node("c")
    a = inv.stub(Rpc.Node, a_servant)
    a.set_next(c_servant)  # the invoker makes a reference for the servant
    (received,) = a_servant.received
    assert type(received) is Rpc.Node and received is not c_servant
    assert received.name() == "c"
    assert received._ref == inv.reference_for(c_servant)
    assert received._ref.repo_id == "IDL:Rpc/Node:1.0"
    a.set_next(c_servant)  # the same servant: the same reference
    assert a_servant.received[1] == received


def test_receive_a_reference_to_a_new_object(gen: SimpleNamespace, inv: CountingInvoker) -> None:
    Rpc, Node = gen.Rpc, gen.impl.Node
    root_servant = Node("root")
    root = inv.stub(Rpc.Node, root_servant)
    kid = root.make_child("kid")  # the servant returns a local servant
    assert type(kid) is Rpc.Node
    assert kid.name() == "kid"
    kid.set_next(root)
    assert root_servant.children[0].next().name() == "root"
    assert kid.next() == root


def test_nil_references(gen: SimpleNamespace, inv: CountingInvoker) -> None:
    Rpc, Node = gen.Rpc, gen.impl.Node
    servant = Node("n")
    node = inv.stub(Rpc.Node, servant)
    assert node.next() is None
    node.set_next(None)
    assert servant.received == [None]
    assert node.make_child("") is None
    assert node.echo_object(None) is None
    assert node.echo_base(None) is None
    assert node.swap(None) is None


def test_inout_reference(gen: SimpleNamespace, inv: CountingInvoker) -> None:
    Rpc, Node = gen.Rpc, gen.impl.Node
    node = inv.stub(Rpc.Node, Node("n"))
    first, second = inv.stub(Rpc.Node, Node("first")), Node("second")
    assert node.swap(first) is None
    old = node.swap(second)
    assert type(old) is Rpc.Node and old == first and old.name() == "first"
    assert node.next().name() == "second"


def test_derived_reference_as_base_parameter(gen: SimpleNamespace, inv: CountingInvoker) -> None:
    Rpc = gen.Rpc
    node_servant = gen.impl.Node("n")
    node = inv.stub(Rpc.Node, node_servant)
    diamond = inv.stub(Rpc.Diamond, gen.impl.Diamond())
    got = node.echo_base(diamond)
    (received,) = node_servant.received
    assert type(received) is Rpc.Base  # the declared interface
    assert received._ref.repo_id == "IDL:Rpc/Diamond:1.0"  # the object's own type travels
    assert type(got) is Rpc.Base and got.base_op(2) == 20
    assert got._narrow(Rpc.Diamond).diamond_op() == "diamond"


def test_object_typed_parameter(gen: SimpleNamespace, inv: CountingInvoker) -> None:
    Rpc = gen.Rpc
    node_servant = gen.impl.Node("n")
    node = inv.stub(Rpc.Node, node_servant)
    other = inv.stub(Rpc.Node, gen.impl.Node("other"))
    got = node.echo_object(other)
    (received,) = node_servant.received
    assert type(received) is Stub and type(got) is Stub  # Object: the base stub
    assert received == other and got == other
    assert got._ref.repo_id == "IDL:Rpc/Node:1.0"
    assert got._narrow(Rpc.Node).name() == "other"
    # any interface, and a local servant, may be passed as an Object
    diamond = gen.impl.Diamond()
    assert node.echo_object(diamond)._narrow(Rpc.Diamond).diamond_op() == "diamond"


def test_sequence_of_references(gen: SimpleNamespace, inv: CountingInvoker) -> None:
    Rpc, Node = gen.Rpc, gen.impl.Node
    servant = Node("list")
    node = inv.stub(Rpc.Node, servant)
    a, b = inv.stub(Rpc.Node, Node("a")), Node("b")
    got = node.reverse([a, b, None])
    assert [type(x) for x in servant.received[0]] == [Rpc.Node, Rpc.Node, type(None)]
    assert got[0] is None and [x.name() for x in got[1:]] == ["b", "a"]
    assert node.reverse([]) == []


def test_reference_argument_of_the_wrong_kind_is_bad_param(
    gen: SimpleNamespace, inv: CountingInvoker
) -> None:
    node = inv.stub(gen.Rpc.Node, gen.impl.Node("n"))
    sent = len(inv.sent)
    for wrong in (42, "IDL:Rpc/Node:1.0", object()):
        with pytest.raises(BAD_PARAM):
            node.set_next(wrong)
        with pytest.raises(BAD_PARAM):
            node.echo_object(wrong)
    assert len(inv.sent) == sent
