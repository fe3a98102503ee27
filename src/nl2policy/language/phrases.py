"""Hand-written wordings of each domain's questions and actions, for the synthetic generator.

Each question has statements that are true on its yes branch (`pos`) and on its no branch
(`neg`) and a clipped form for arrow and bullet styles (`short`, `short_no`). Written for this
project from the briefing's wording, not from the corpus descriptions, so the synthetic data
adds phrasings rather than copying writers. Pseudo-code names are not written at all: they are
made from the question's own id (`code_names`), so none is a name a writer invented.
"""

from __future__ import annotations

QUESTIONS: dict[str, dict[str, dict[str, list[str]]]] = {
    "taxi": {
        "at_airport": {
            "pos": ["the taxi is at the airport", "it is at the airport", "you are at the airport", "I am at the airport", "we're at the airport"],
            "neg": ["the taxi is not at the airport", "it isn't at the airport", "you are not at the airport", "I'm somewhere other than the airport"],
            "short": ["at the airport", "at airport", "airport"], "short_no": ["not at the airport", "elsewhere"]},
        "at_village": {
            "pos": ["the taxi is at the village", "it is in the village", "you are in the village", "I am at the village", "we're in the village"],
            "neg": ["the taxi is not at the village", "it is not in the village", "you aren't in the village", "I'm away from the village"],
            "short": ["in the village", "at village", "village"], "short_no": ["not in the village", "away from the village"]},
        "at_city": {
            "pos": ["the taxi is in the city", "it is in the city", "you are in the city", "I'm in the city", "we are downtown in the city"],
            "neg": ["the taxi is not in the city", "it isn't in the city", "you are not in the city", "I am outside the city"],
            "short": ["in the city", "at city", "city"], "short_no": ["not in the city", "outside the city"]},
        "has_passenger": {
            "pos": ["the taxi has a passenger", "there is a passenger on board", "someone is in the back seat", "you have a passenger", "I've got a rider", "a passenger is aboard"],
            "neg": ["the taxi is empty", "there is no passenger", "nobody is on board", "you don't have a passenger", "the back seat is empty", "no one is in the car"],
            "short": ["passenger aboard", "got a passenger", "someone on board", "have a passenger"], "short_no": ["no passenger", "empty", "nobody aboard"]},
        "heavy_traffic": {
            "pos": ["the traffic to the city is heavy", "the road to the city is jammed", "there is heavy traffic on the city road", "the city road is congested", "traffic is bad"],
            "neg": ["the traffic to the city is light", "the road to the city is clear", "there is no heavy traffic", "the city road is not jammed", "traffic is fine"],
            "short": ["heavy traffic", "city road jammed", "traffic bad"], "short_no": ["traffic light", "road clear", "no jam"]},
        "long_wait": {
            "pos": ["the wait at the village is long", "there is a long wait for a passenger in the village", "the village wait is long", "passengers are slow to show up at the village"],
            "neg": ["the wait at the village is short", "the village wait is not long", "there is no long wait in the village", "passengers show up quickly at the village"],
            "short": ["long wait", "village wait long", "slow village"], "short_no": ["short wait", "wait is short"]},
    },
    "highway": {
        "car_ahead_close": {
            "pos": ["there is a car close in front", "a car is close ahead in my lane", "someone is right in front of you", "the car ahead is close", "the gap ahead is small"],
            "neg": ["nobody is close in front", "the road ahead is clear", "there is no car close ahead", "the lane in front is empty", "the gap ahead is big"],
            "short": ["car close ahead", "car in front", "blocked ahead"], "short_no": ["clear ahead", "nothing in front", "road open"]},
        "car_behind_close": {
            "pos": ["there is a car close behind", "someone is right behind me", "a car is tailgating you", "the car behind is close"],
            "neg": ["nobody is close behind", "there is no car close behind", "the lane behind is clear", "no one is tailgating"],
            "short": ["car close behind", "tailgater", "car behind"], "short_no": ["nothing behind", "clear behind"]},
        "left_lane_free": {
            "pos": ["the left lane is free", "the lane to my left is clear", "there is room on the left", "you can move left safely"],
            "neg": ["the left lane is not free", "the lane on the left is blocked", "there is no room on the left", "the left side is taken"],
            "short": ["left free", "left lane clear", "room on the left"], "short_no": ["left blocked", "left taken"]},
        "right_lane_free": {
            "pos": ["the right lane is free", "the lane to my right is clear", "there is room on the right", "you can move right safely"],
            "neg": ["the right lane is not free", "the lane on the right is blocked", "there is no room on the right", "the right side is taken"],
            "short": ["right free", "right lane clear", "room on the right"], "short_no": ["right blocked", "right taken"]},
        "in_left_lane": {
            "pos": ["I am in the leftmost lane", "the car is in the left lane", "you are in the far left lane", "we're in the leftmost lane"],
            "neg": ["I am not in the leftmost lane", "the car is not in the left lane", "you aren't in the far left lane"],
            "short": ["leftmost lane", "in left lane", "far left"], "short_no": ["not leftmost", "not in left lane"]},
        "in_right_lane": {
            "pos": ["I am in the rightmost lane", "the car is in the right lane", "you are in the far right lane", "we're in the rightmost lane"],
            "neg": ["I am not in the rightmost lane", "the car is not in the right lane", "you aren't in the far right lane"],
            "short": ["rightmost lane", "in right lane", "far right"], "short_no": ["not rightmost", "not in right lane"]},
        "going_fast": {
            "pos": ["I am driving fast", "the car is going fast", "you are already fast", "my speed is high"],
            "neg": ["I am not driving fast", "the car is going slowly", "you are slow", "my speed is low"],
            "short": ["going fast", "fast", "speed high"], "short_no": ["slow", "not fast", "speed low"]},
    },
}

def code_names(question: str) -> list[str]:
    """Names a pseudo-code writer might give a question, made from its id alone:
    at_airport -> at_airport, atAirport, AtAirport, AT_AIRPORT, isAtAirport."""
    head, *rest = question.split("_")
    camel = head + "".join(part.title() for part in rest)
    pascal = camel[0].upper() + camel[1:]
    return [question, camel, pascal, question.upper(), "is" + pascal]


ACTIONS: dict[str, dict[str, list[str]]] = {
    "taxi": {
        "go_airport": ["drive to the airport", "head to the airport", "go to the airport", "take them to the airport", "drive straight to the airport"],
        "go_village": ["drive to the village", "head to the village", "go to the village", "go back to the village"],
        "go_city": ["drive to the city", "head to the city", "go to the city", "go into town to the city"],
        "wait": ["wait for a passenger", "wait here", "stay and wait", "sit tight until someone shows up", "wait where it is"],
    },
    "highway": {
        "lane_left": ["change to the left lane", "move left", "switch lanes to the left", "change left"],
        "lane_right": ["change to the right lane", "move right", "switch lanes to the right", "change right"],
        "faster": ["speed up", "accelerate", "go faster", "step on the gas"],
        "slower": ["slow down", "brake", "ease off", "go slower"],
        "idle": ["keep my lane and speed", "stay in lane at the same speed", "do nothing", "just keep going as I am", "keep lane and speed"],
    },
}

FILLER = [
    "Here's my plan.", "That's it, keep it simple.", "It's been raining all morning.", "I think this is a good plan.",
    "Repeat this all the time.", "Hope that makes sense!", "My cousin drives like this too.", "Anyway.",
    "I tried to keep it short.", "Good luck out there.",
]

REASONS: dict[str, dict[str, list[str]]] = {
    "taxi": {
        "go_airport": ["that's where the fare gets paid", "every passenger wants to go there", "the money is at the airport",
                       "dropping them off earns the fare"],
        "go_village": ["the village never has traffic", "the road there is always quick", "someone may turn up there soon"],
        "go_city": ["there are always people waiting there", "the city is never short of passengers", "a fare is guaranteed there"],
        "wait": ["someone will show up soon", "driving off would waste time", "it saves a pointless trip"],
    },
    "highway": {
        "lane_left": ["it gets me around the slow car", "there is more room over there", "passing beats sitting behind someone"],
        "lane_right": ["keeping right is rewarded", "the right-hand lanes pay more", "that's where the bonus is"],
        "faster": ["going fast earns more", "speed is rewarded", "the road lets me"],
        "slower": ["a crash costs far more than speed earns", "hitting the car in front is the worst outcome", "safety comes first"],
        "idle": ["everything is fine as it is", "there's no need to change anything", "nothing needs fixing"],
    },
}
"""Why-clauses writers tack onto actions ("drive to the city, because ..."); they carry no policy."""

ASIDES = [
    "I don't look at {q} at all.", "{Q} plays no part in this plan.", "I thought about {q} but left it out.",
    "I never bother checking {q}.", "I ignore {q} here.", "Forget about {q}, it doesn't matter.",
]
"""Sentences about a question the tree does *not* ask: long descriptions mention what was left out."""

UNUSED_ACTIONS = ["I never {a} in this plan.", "There's no reason to {a} here.", "It doesn't ever {a}."]

SUMMARIES = ["In short: ", "So to sum up: ", "To repeat it simply: ", "Basically: ", "Put simply, "]
"""Lead-ins to a second, compressed pass over the policy (explainers restate their plan)."""
