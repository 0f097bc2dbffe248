"""Distances from vehicles to obstacles: the buildings (axis-aligned boxes) and the arena walls.

All functions are batched by broadcasting over any leading shape; there is no loop over
vehicles, boxes or environments. Distances are signed: positive outside every obstacle,
negative inside one (a vehicle can sink into a wall during a control step before the collision
step pushes it out).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import torch
from torch import Tensor


def nearest_obstacle_xy(
    px: Tensor, py: Tensor, boxes: Tensor, arena: Tensor
) -> tuple[Tensor, Tensor, Tensor]:
    """Signed distance and surface normal of the nearest obstacle, on separate components.

    Args:
        px, py: positions (...), metres.
        boxes: buildings (B, 4) as [xmin, ymin, xmax, ymax], metres; B may be 0.
        arena: (2,) arena width and height, metres; the walls are the border of
            [0, width] x [0, height].

    Returns:
        distance: (...) signed distance to the nearest obstacle surface (m), negative inside.
        nx, ny: (...) unit normal of that surface, pointing out of the obstacle. The nearest
            surface point is ``(px, py) - (nx, ny) * distance``.
    """
    # Walls: the distance to each side (left, right, bottom, top), measured inwards; keep the
    # nearest side, whose inward normal is +-x or +-y.
    walls = torch.stack([px, arena[0] - px, py, arena[1] - py], dim=-1)
    dist, side = walls.min(dim=-1)
    nx = (side == 0).to(px.dtype) - (side == 1).to(px.dtype)
    ny = (side == 2).to(px.dtype) - (side == 3).to(px.dtype)
    if boxes.shape[0] > 0:
        # Buildings: the box signed-distance function around centre and half size.
        cx, cy = (boxes[:, 0] + boxes[:, 2]) * 0.5, (boxes[:, 1] + boxes[:, 3]) * 0.5
        hx, hy = (boxes[:, 2] - boxes[:, 0]) * 0.5, (boxes[:, 3] - boxes[:, 1]) * 0.5
        rx, ry = px.unsqueeze(-1) - cx, py.unsqueeze(-1) - cy  # (..., B)
        ex, ey = rx.abs() - hx, ry.abs() - hy
        box_dist = torch.sqrt(ex.clamp(min=0) ** 2 + ey.clamp(min=0) ** 2) + torch.maximum(
            ex, ey
        ).clamp(max=0)
        best_dist, best = box_dist.min(dim=-1)
        index = best.unsqueeze(-1)
        rx, ry = rx.gather(-1, index).squeeze(-1), ry.gather(-1, index).squeeze(-1)
        ex, ey = ex.gather(-1, index).squeeze(-1), ey.gather(-1, index).squeeze(-1)
        sx, sy = torch.where(rx >= 0, 1.0, -1.0), torch.where(ry >= 0, 1.0, -1.0)
        ox, oy = ex.clamp(min=0), ey.clamp(min=0)
        out_len = torch.sqrt(ox * ox + oy * oy)
        outside = out_len > 0
        # Outside: the normal points from the box to the vehicle; inside: out of the nearest face.
        inv = 1.0 / out_len.clamp(min=1e-12)
        x_face = ex >= ey
        bnx = torch.where(outside, sx * ox * inv, torch.where(x_face, sx, 0.0))
        bny = torch.where(outside, sy * oy * inv, torch.where(x_face, 0.0, sy))
        closer = best_dist < dist
        dist = torch.where(closer, best_dist, dist)
        nx, ny = torch.where(closer, bnx, nx), torch.where(closer, bny, ny)
    return dist, nx, ny


def obstacle_distances_xy(
    px: Tensor, py: Tensor, boxes: Tensor, arena: Tensor
) -> tuple[Tensor, Tensor, Tensor]:
    """Signed distance and outward normal of every obstacle: the B buildings, then the four
    walls (left, right, bottom, top).

    Args:
        px, py: positions (...), metres. boxes: (B, 4). arena: (2,) width and height.

    Returns:
        distance, nx, ny: (..., B + 4) each; the nearest point of obstacle k is
        ``(px, py) - (nx[..., k], ny[..., k]) * distance[..., k]``.
    """
    px, py = px.unsqueeze(-1), py.unsqueeze(-1)
    cx, cy = (boxes[:, 0] + boxes[:, 2]) * 0.5, (boxes[:, 1] + boxes[:, 3]) * 0.5
    hx, hy = (boxes[:, 2] - boxes[:, 0]) * 0.5, (boxes[:, 3] - boxes[:, 1]) * 0.5
    rx, ry = px - cx, py - cy  # (..., B)
    ex, ey = rx.abs() - hx, ry.abs() - hy
    sx, sy = torch.where(rx >= 0, 1.0, -1.0), torch.where(ry >= 0, 1.0, -1.0)
    ox, oy = ex.clamp(min=0), ey.clamp(min=0)
    out_len = torch.sqrt(ox * ox + oy * oy)
    dist = out_len + torch.maximum(ex, ey).clamp(max=0)
    inv = 1.0 / out_len.clamp(min=1e-12)
    x_face = ex >= ey
    nx = torch.where(out_len > 0, sx * ox * inv, torch.where(x_face, sx, 0.0))
    ny = torch.where(out_len > 0, sy * oy * inv, torch.where(x_face, 0.0, sy))
    one, zero = torch.ones_like(px), torch.zeros_like(px)
    wall_dist = torch.cat([px, arena[0] - px, py, arena[1] - py], dim=-1)
    wall_nx = torch.cat([one, -one, zero, zero], dim=-1)
    wall_ny = torch.cat([zero, zero, one, -one], dim=-1)
    return (
        torch.cat([dist, wall_dist], -1),
        torch.cat([nx, wall_nx], -1),
        torch.cat([ny, wall_ny], -1),
    )


def pick_nearest(
    dist: Tensor, nx: Tensor, ny: Tensor, num_boxes: int
) -> tuple[Tensor, Tensor, Tensor]:
    """The nearest of the obstacles measured by :func:`obstacle_distances_xy` (..., B + 4):
    its distance and normal (...), each, with :func:`nearest_obstacle_xy`'s choice on ties
    (the first wall, else the first building; a wall over a building at equal distance)."""
    wall_dist, side = dist[..., num_boxes:].min(dim=-1)
    index = side + num_boxes
    if num_boxes > 0:
        box_dist, box = dist[..., :num_boxes].min(dim=-1)
        closer = box_dist < wall_dist
        index = torch.where(closer, box, index)
        wall_dist = torch.where(closer, box_dist, wall_dist)
    index = index.unsqueeze(-1)
    return wall_dist, nx.gather(-1, index).squeeze(-1), ny.gather(-1, index).squeeze(-1)


def nearest_obstacle(pos: Tensor, boxes: Tensor, arena: Tensor) -> tuple[Tensor, Tensor, Tensor]:
    """:func:`nearest_obstacle_xy` for stacked positions (..., 2); returns the signed distance
    (...), the nearest surface point (..., 2) and the outward normal (..., 2)."""
    dist, nx, ny = nearest_obstacle_xy(pos[..., 0], pos[..., 1], boxes, arena)
    normal = torch.stack([nx, ny], dim=-1)
    return dist, pos - normal * dist.unsqueeze(-1), normal


def ray_distance(
    ox: Tensor,
    oy: Tensor,
    directions: Tensor,
    boxes: Tensor,
    arena: Tensor,
    margin: float,
    max_distance: float,
) -> Tensor:
    """Free distance along rays before they come within ``margin`` of an obstacle.

    Args:
        ox, oy: ray origins (...), metres.
        directions: unit directions (M, 2).
        boxes: buildings (B, 4) [xmin, ymin, xmax, ymax]; B may be 0.
        arena: (2,) arena width and height; the walls are its border.
        margin: clearance kept from every obstacle (m): boxes grow and the arena shrinks by it.
        max_distance: cap on the result (m).

    Returns:
        (..., M) distances in [0, max_distance]; 0 for rays that start inside the margin and
        head further in (rays that start inside and head out are free of that obstacle).
    """
    dx, dy = directions[:, 0], directions[:, 1]  # (M,)
    inv_x = 1.0 / torch.where(dx.abs() < 1e-9, 1e-9, dx)
    inv_y = 1.0 / torch.where(dy.abs() < 1e-9, 1e-9, dy)
    ox, oy = ox.unsqueeze(-1), oy.unsqueeze(-1)  # (..., 1)
    # Walls: leaving [margin, size - margin] along each axis.
    wall_x = torch.where(dx > 0, (arena[0] - margin - ox) * inv_x, (margin - ox) * inv_x)
    wall_y = torch.where(dy > 0, (arena[1] - margin - oy) * inv_y, (margin - oy) * inv_y)
    wall_x = torch.where(dx.abs() < 1e-9, max_distance, wall_x)
    wall_y = torch.where(dy.abs() < 1e-9, max_distance, wall_y)
    dist = torch.minimum(wall_x, wall_y).clamp(min=0.0, max=max_distance)  # (..., M)
    if boxes.shape[0] > 0:
        # Slab test against every box grown by the margin: (..., M, B).
        ox3, oy3 = ox.unsqueeze(-1), oy.unsqueeze(-1)
        ix, iy = inv_x.unsqueeze(-1), inv_y.unsqueeze(-1)  # (M, 1)
        tx0, tx1 = (boxes[:, 0] - margin - ox3) * ix, (boxes[:, 2] + margin - ox3) * ix
        ty0, ty1 = (boxes[:, 1] - margin - oy3) * iy, (boxes[:, 3] + margin - oy3) * iy
        t_enter = torch.maximum(torch.minimum(tx0, tx1), torch.minimum(ty0, ty1))
        t_exit = torch.minimum(torch.maximum(tx0, tx1), torch.maximum(ty0, ty1))
        hit = (t_enter <= t_exit) & (t_exit > 0.0)
        # A ray that starts inside a grown box is blocked at once if it heads towards the box's
        # centre, and not blocked by that box if it heads away (it is leaving the margin).
        inside = t_enter < 0.0
        towards = (
            dx[:, None] * ((boxes[:, 0] + boxes[:, 2]) * 0.5 - ox3)
            + dy[:, None] * ((boxes[:, 1] + boxes[:, 3]) * 0.5 - oy3)
        ) > 0
        hit = hit & (~inside | towards)
        t_hit = torch.where(hit, t_enter.clamp(min=0.0), max_distance)
        dist = torch.minimum(dist, t_hit.amin(dim=-1))
    return dist


def segment_clear(a: Tensor, b: Tensor, boxes: Tensor) -> Tensor:
    """Whether the straight segments from ``a`` to ``b`` (..., 2) miss every building (B, 4)
    [xmin, ymin, xmax, ymax] (m); a segment that only grazes a box's surface is clear.
    Returns (...) bool."""
    if boxes.shape[0] == 0:
        shape = torch.broadcast_shapes(a.shape, b.shape)[:-1]
        return torch.ones(shape, dtype=torch.bool, device=a.device)
    d = b - a
    d = torch.where(d.abs() < 1e-9, torch.full_like(d, 1e-9), d)
    a, d = a.unsqueeze(-2), d.unsqueeze(-2)  # (..., 1, 2) against (B, 2)
    t0 = (boxes[:, :2] - a) / d
    t1 = (boxes[:, 2:] - a) / d
    t_enter = torch.minimum(t0, t1).amax(-1).clamp(min=0.0)  # (..., B)
    t_exit = torch.maximum(t0, t1).amin(-1).clamp(max=1.0)
    return ~(t_enter < t_exit).any(-1)


class Roadmap(NamedTuple):
    """The shortest paths round the buildings, for :func:`geodesic_distance`: waypoints just
    off every building corner that lies inside the arena and outside every other building, and
    the length of the shortest waypoint-to-waypoint path between each pair."""

    nodes: Tensor  # (K, 2) m
    between: Tensor  # (K, K) m, inf where no path joins them


def build_roadmap(boxes: Tensor, arena: Tensor, margin: float) -> Roadmap:
    """The :class:`Roadmap` of buildings ``boxes`` (B, 4) in an arena (2,) of walls, with the
    waypoints ``margin`` (m) off each corner along both axes."""
    if boxes.shape[0] == 0:
        empty = boxes.new_zeros((0, 2))
        return Roadmap(empty, boxes.new_zeros((0, 0)))
    x0, y0, x1, y1 = boxes.unbind(-1)
    corners = torch.stack(
        [
            torch.stack([x0 - margin, y0 - margin], -1),
            torch.stack([x1 + margin, y0 - margin], -1),
            torch.stack([x0 - margin, y1 + margin], -1),
            torch.stack([x1 + margin, y1 + margin], -1),
        ],
        dim=1,
    ).reshape(-1, 2)
    inside_arena = ((corners > 0) & (corners < arena)).all(-1)
    in_box = (
        (corners[:, None, :] > boxes[None, :, :2]) & (corners[:, None, :] < boxes[None, :, 2:])
    ).all(-1)
    nodes = corners[inside_arena & ~in_box.any(-1)]
    length = (nodes[:, None] - nodes[None]).norm(dim=-1).double()
    between = torch.where(segment_clear(nodes[:, None], nodes[None], boxes), length, math.inf)
    for k in range(len(nodes)):  # Floyd-Warshall
        between = torch.minimum(between, between[:, k : k + 1] + between[k : k + 1, :])
    return Roadmap(nodes, between.to(boxes.dtype))


def geodesic_distance(p: Tensor, q: Tensor, boxes: Tensor, roadmap: Roadmap) -> Tensor:
    """Length (m) of the shortest path from ``p`` (..., M, 2) to ``q`` (..., 2) that goes round
    the buildings ``boxes`` (B, 4): the straight distance where the segment is clear, else the
    shortest path through the roadmap's waypoints (the straight distance if none joins them).
    Returns (..., M)."""
    q = q.unsqueeze(-2)  # (..., 1, 2)
    direct = (p - q).norm(dim=-1)
    if roadmap.nodes.shape[0] == 0:
        return direct
    nodes = roadmap.nodes
    p_leg = torch.where(
        segment_clear(p.unsqueeze(-2), nodes, boxes),
        (p.unsqueeze(-2) - nodes).norm(dim=-1),
        math.inf,
    )  # (..., M, K)
    q_leg = torch.where(
        segment_clear(q.unsqueeze(-2), nodes, boxes),
        (q.unsqueeze(-2) - nodes).norm(dim=-1),
        math.inf,
    )  # (..., 1, K)
    to_q = (roadmap.between + q_leg.unsqueeze(-2)).amin(-1)  # (..., 1, K): waypoint a to q
    around = (p_leg + to_q).amin(-1)
    path = torch.where(segment_clear(p, q, boxes), direct, around)
    return torch.where(torch.isfinite(path), path, direct)
