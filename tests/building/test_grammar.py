import pytest

from jarena.building.grammar import ArenaStringError, Call, parse_arena_string


def test_parses_pairs_numbers_names_calls_lists():
    p = parse_arena_string("classic|domain:cartpole,task:balance,action:[rescale(-1,1.5),repeat(times=2)],"
                           "time_limit:100,x:-2.5e-1,flag:true,s:'a b'")
    assert p.builder == "classic"
    assert p.pairs["domain"] == "cartpole" and p.pairs["time_limit"] == 100
    assert p.pairs["action"] == [Call("rescale", (-1, 1.5)), Call("repeat", (), (("times", 2),))]
    assert p.pairs["x"] == -0.25 and p.pairs["flag"] is True and p.pairs["s"] == "a b"


def test_whitespace_and_bare_builder():
    assert parse_arena_string(" classic | domain : cartpole ").pairs == {"domain": "cartpole"}
    assert parse_arena_string("classic").pairs == {}
    assert parse_arena_string("classic|").pairs == {}


def test_round_trip():
    text = "classic|domain:cartpole,action:[rescale(-1,1),repeat(2)],wrap:reward_scale(0.1)"
    assert str(parse_arena_string(text)) == text
    assert str(parse_arena_string(str(parse_arena_string(text)))) == text


@pytest.mark.parametrize("text, message", [
    ("", "empty arena string"),
    ("classic|domain", "expected ':' after key 'domain'"),
    ("classic|domain:", "expected a value"),
    ("classic|domain:cartpole,", "expected a key name"),
    ("classic|domain:a,domain:b", "key 'domain' given twice"),
    ("classic|action:repeat(2", "to close repeat"),
    ("classic|action:[repeat(2)", "to close the list"),
    ("classic|domain:cart$pole", "unexpected character '\\$'"),
    ("classic|domain:cartpole task:x", "expected '\\|', ',' or the end"),
    ("classic|action:f(a=1,2)", "positional argument after keyword"),
    ("|domain:x", "expected a builder name"),
])
def test_malformed_strings_point_at_the_problem(text, message):
    with pytest.raises(ArenaStringError, match=message) as e:
        parse_arena_string(text)
    if text:
        assert "^" in str(e.value)  # a caret under the offending position
