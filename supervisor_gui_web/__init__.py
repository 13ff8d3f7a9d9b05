"""The web supervisor: a dashboard backend (aiohttp) for one or more device servers, and its page."""
from landscape.supervisor.app import RunningDashboard, create_app, start
from landscape.supervisor.config import DashboardConfig, DeviceTarget, parse_device

__all__ = ["DashboardConfig", "DeviceTarget", "RunningDashboard", "create_app", "parse_device", "start"]
